#!/usr/bin/env bash
# The main job on a sample scan: what the file holds, then its range-image features.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${1:-build}"
SCAN=samples/kitti00_000000.bin
mkdir -p out
"$BUILD_DIR/lex3d" info "$SCAN"
"$BUILD_DIR/lex3d" features "$SCAN" --png out/kitti00_000000_features.png
