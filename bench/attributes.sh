#!/usr/bin/env bash
# Cost of the intensity attribute, bits a point: lex3d's ATTR chunk (formats/model.md §2.10)
# beside Draco (colour channel, exact) and G-PCC reflectance (tmc3, lossless) on real scans.
# Usage: [TMC3=/path/to/tmc3] [DATA=/work/shared/data] bench/attributes.sh [--max-error E] [--lex3d BIN]
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
LEX3D=$BUILD_DIR/lex3d
DATA=${DATA:-../shared/data}
TMC3=${TMC3:-}
E=0.02
while [ $# -gt 0 ]; do
  case "$1" in
    --max-error) E="$2"; shift ;;
    --lex3d) LEX3D="$2"; shift ;;
    -h|--help) sed -n '2,4p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "attributes.sh: unknown option $1" >&2; exit 1 ;;
  esac
  shift
done
[ -x "$LEX3D" ] || { echo "attributes.sh: no lex3d binary at $LEX3D (build it, or give --lex3d)" >&2; exit 1; }
scans=()
[ -f "$DATA/kitti00/000000.bin" ] && scans+=("kitti00/0=$DATA/kitti00/000000.bin")
[ -f "$DATA/kitti00/000001.bin" ] && scans+=("kitti00/1=$DATA/kitti00/000001.bin")
[ -f "$DATA/balm/000000.bin" ] && scans+=("balm/0=$DATA/balm/000000.bin")
for f in "$DATA"/ouster/*.pcap; do [ -f "$f" ] && scans+=("ouster/$(basename "$f" .pcap)=$f") && break; done
for f in "$DATA"/las/*.las; do [ -f "$f" ] && scans+=("las/$(basename "$f" .las)=$f") && break; done
[ ${#scans[@]} -gt 0 ] || { echo "attributes.sh: no scans found under $DATA" >&2; exit 1; }
gpcc=()
[ -n "$TMC3" ] && gpcc=(--tmc3 "$TMC3")
/usr/bin/python3 bench/attributes.py --lex3d "$LEX3D" --max-error "$E" ${gpcc[@]+"${gpcc[@]}"} "${scans[@]}"
