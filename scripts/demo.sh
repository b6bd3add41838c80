#!/usr/bin/env bash
# The main job on a sample scan: compress it into a lex3d model file, show the file,
# decompress it and measure the reconstruction against the original (bits per input
# point, D1 PSNR, inliers).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${1:-build}"
SCAN=samples/kitti00_000000.bin
mkdir -p out
"$BUILD_DIR/lex3d" compress "$SCAN" -o out/kitti00_000000.lex3dm
"$BUILD_DIR/lex3d" info out/kitti00_000000.lex3dm
"$BUILD_DIR/lex3d" decompress out/kitti00_000000.lex3dm -o out/kitti00_000000_decoded.ply --reference "$SCAN"
# The same scan with a residual layer: every point within 14 mm, both ways.
"$BUILD_DIR/lex3d" compress "$SCAN" -o out/kitti00_000000_e14mm.lex3dm --max-error 0.014
"$BUILD_DIR/lex3d" decompress out/kitti00_000000_e14mm.lex3dm -o out/kitti00_000000_e14mm.ply --reference "$SCAN"
