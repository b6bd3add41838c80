#!/usr/bin/env bash
# Feature extraction benchmark: per-stage time per scan (median, one core), interest
# and coverage points per scan, peak memory; then lex3d's range image against
# pcl::RangeImage. Needs a Release build (scripts/setup.sh) and ../shared/data.
# Usage: bench/features.sh [BUILD_DIR] [DATA_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${1:-build}"
DATA="${2:-../shared/data}"
if [ ! -d "$DATA/balm" ] || [ ! -d "$DATA/kitti00" ]; then
  echo "bench/features.sh: $DATA/balm and $DATA/kitti00 are needed" >&2
  exit 1
fi
cmake --build "$BUILD_DIR" --target lex3d_bench_features lex3d_bench_range_pcl -j2 >/dev/null
"$BUILD_DIR/bench/lex3d_bench_features" --threads 1 "$DATA/balm" "$DATA/kitti00" "$DATA/newer_college" \
  "$DATA/indoor/room_scan1.pcd"
echo
"$BUILD_DIR/bench/lex3d_bench_range_pcl" "$DATA/kitti00/000000.bin" "$DATA/balm/000040.bin" \
  "$DATA/newer_college/raw_00.bin"
