#!/usr/bin/env bash
# Scans of lidars that are not in the shared data, made from real scans that are: every
# table in bench/sensors/ (vendor laser tables of the Velodyne VLP-32C, VLS-128, VLP-16
# Hi-Res, HDL-64E S2, Hesai Pandar40P, Pandar64, PandarXT-32, OT128 and RoboSense RS-LiDAR-32; see
# bench/sensors/README.md) is cast into KITTI HDL-64E scans and Ouster OS-1-128 turns by
# bench/sensor_resample.py (1 cm range noise, the sensor's distance resolution, encoder
# jitter, firing times). Writes OUT/<sensor>/<source>.bin (float32 x y z intensity=0, no
# ring, in firing order) and OUT/<sensor>/table.json; bench/rd.sh --resampled OUT measures them.
#
# Usage: bench/resample_sets.sh [--lex3d BIN] [DATA_DIR] [OUT_DIR]
#   DATA_DIR  the real scans (default ../shared/data); OUT_DIR default out/resampled
set -euo pipefail
cd "$(dirname "$0")/.."
LEX3D=build/lex3d
if [ "${1:-}" = "--lex3d" ]; then LEX3D="$2"; shift 2; fi
DATA="${1:-../shared/data}"
OUT="${2:-out/resampled}"
[ -x "$LEX3D" ] || { echo "resample_sets.sh: $LEX3D missing (build first)" >&2; exit 1; }
/usr/bin/python3 -c 'import numpy, scipy' 2> /dev/null || { echo "resample_sets.sh: needs python3-numpy and python3-scipy" >&2; exit 1; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
sources=()
for k in 000000 000005; do
  [ -f "$DATA/kitti00/$k.bin" ] && sources+=("$DATA/kitti00/$k.bin")
done
os1="$DATA/ouster/OS-1-128_v2.3.0_1024x10_lb_n3.pcap"
if [ -f "$os1" ]; then
  "$LEX3D" convert "$os1" "$tmp/os1_128.bin" > /dev/null
  sources+=("$tmp"/os1_128_00[02].bin)
fi
[ ${#sources[@]} -gt 0 ] || { echo "resample_sets.sh: no source scans under $DATA" >&2; exit 1; }
for table in bench/sensors/*.json; do
  sensor="$(basename "$table" .json)"
  mkdir -p "$OUT/$sensor"
  cp "$table" "$OUT/$sensor/table.json"
  seed=1
  for src in "${sources[@]}"; do
    name="$(basename "$src" .bin)"
    [[ "$src" == "$DATA/kitti00/"* ]] && name="kitti00_$name"
    /usr/bin/python3 bench/sensor_resample.py --seed "$seed" "$src" "$table" "$OUT/$sensor/$name.bin"
    seed=$((seed + 1))
  done
done
echo "resample_sets.sh: ${#sources[@]} source scans x $(ls bench/sensors/*.json | wc -l) sensors in $OUT"
