#!/usr/bin/env bash
# The main job on a sample scan: compress it into a lex3d model file (the default bound:
# every point within 1 cm, both ways), show the file, decompress it and measure the
# reconstruction against the original (bits per input point, D1 PSNR, Hausdorff distance).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${1:-build}"
SCAN=samples/kitti00_000000.bin
mkdir -p out
"$BUILD_DIR/lex3d" compress "$SCAN" -o out/kitti00_000000.lex3dm
"$BUILD_DIR/lex3d" info out/kitti00_000000.lex3dm
"$BUILD_DIR/lex3d" decompress out/kitti00_000000.lex3dm -o out/kitti00_000000_decoded.ply --reference "$SCAN"
# The words of a learned alphabet alone, no bound: the scan's structure in a few bits a point.
"$BUILD_DIR/lex3d" compress "$SCAN" -o out/kitti00_000000_words.lex3dm --max-error none
"$BUILD_DIR/lex3d" decompress out/kitti00_000000_words.lex3dm -o out/kitti00_000000_words.ply --reference "$SCAN"
