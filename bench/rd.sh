#!/usr/bin/env bash
# Rate–distortion benchmark: lex3d against MPEG G-PCC (octree, and predictive geometry with
# angular coding; when TMC3=/path/to/tmc3 is set), Draco (kd-tree and sequential), PCL's octree
# point cloud compression and OctoMap, on the same real scans. For every codec setting
# and scan: bits per input point, D1 PSNR (peak 59.70 m, symmetric), RMSE, Hausdorff,
# share of input points with a decoded point within 2 cm / 5 cm, encode/decode ms and
# peak memory (/usr/bin/time %M). Prints a table per dataset (medians over scans, and
# bits per point interpolated at equal PSNR 60 / 70 / 75 / 82.2 / 86 dB) and writes
# OUT/report.md, OUT/rows.csv, OUT/rd.json and OUT/rd_<dataset>.png.
#
# Usage: [TMC3=/path/to/tmc3] bench/rd.sh [--all-scans] [--scans N] [--out DIR] [--keep] [--lex3d BIN]
#                                         [BUILD_DIR] [DATA_DIR] [dataset...]
#   BUILD_DIR  a build with LEX3D_BUILD_BENCH=ON (default build)
#   DATA_DIR   the real scans (default ../shared/data)
#   dataset    balm kitti00 newer_college indoor balm_map hdl32e ouster vlp16 las (default: all;
#              balm_map: three maps of 10 balm scans 3 s apart merged in the world frame, made
#              from the poses; ouster, vlp16, las are skipped while lex3d cannot read their files)
#   TMC3       G-PCC's encoder/decoder (TMC13, built outside the project; see bench/README-rd.md);
#              unset: no G-PCC rows
#   --all-scans  every balm scan (default: every 10th, 9 scans)
#   --scans N    at most N scans a data set, evenly spaced (quick runs)
#   --out DIR    results (default out/rd/<datasets joined by ->)
#   --keep       keep the temporary files (reference PLYs, last decoded clouds)
#   --lex3d BIN  the lex3d binary to measure (default BUILD_DIR/lex3d)
#   --resampled DIR  also offer the sets bench/resample_sets.sh wrote to DIR, as datasets
#              rs_<sensor> (other lidars' beam layouts, G-PCC given their exact laser tables)
# Needs: draco_encoder/draco_decoder (Debian package draco), /usr/bin/time, /usr/bin/python3
# with matplotlib — all installed by scripts/setup.sh. See bench/README-rd.md.
set -euo pipefail
cd "$(dirname "$0")/.."

flags=()
pos=()
OUT=""
LEX3D=""
while [ $# -gt 0 ]; do
  case "$1" in
    --all-scans|--keep) flags+=("$1") ;;
    --scans) [ $# -ge 2 ] || { echo "rd.sh: --scans needs a number" >&2; exit 1; }; flags+=(--scans "$2"); shift ;;
    --out) [ $# -ge 2 ] || { echo "rd.sh: --out needs a directory" >&2; exit 1; }; OUT="$2"; shift ;;
    --lex3d) [ $# -ge 2 ] || { echo "rd.sh: --lex3d needs a binary" >&2; exit 1; }; LEX3D="$2"; shift ;;
    --resampled) [ $# -ge 2 ] || { echo "rd.sh: --resampled needs a directory" >&2; exit 1; }; flags+=(--resampled "$2"); shift ;;
    -h|--help) sed -n '2,28p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "rd.sh: unknown option $1" >&2; exit 1 ;;
    *) pos+=("$1") ;;
  esac
  shift
done
BUILD_DIR="${pos[0]:-build}"
DATA="${pos[1]:-../shared/data}"
DATASETS=("${pos[@]:2}")
[ ${#DATASETS[@]} -gt 0 ] || DATASETS=(balm kitti00 newer_college indoor balm_map hdl32e ouster vlp16 las)
[ -n "$OUT" ] || OUT="out/rd/$(IFS=-; echo "${DATASETS[*]}")"
[ -n "$LEX3D" ] || LEX3D="$BUILD_DIR/lex3d"

missing=0
for tool in "$LEX3D" "$BUILD_DIR/bench/lex3d_eval_clouds" "$BUILD_DIR/bench/lex3d_convert" \
            "$BUILD_DIR/bench/lex3d_bench_pcl_octree" "$BUILD_DIR/bench/lex3d_bench_octomap"; do
  [ -x "$tool" ] || { echo "rd.sh: $tool missing (build with -DLEX3D_BUILD_BENCH=ON)" >&2; missing=1; }
done
for tool in draco_encoder draco_decoder /usr/bin/time /usr/bin/python3; do
  command -v "$tool" > /dev/null || { echo "rd.sh: $tool missing (run scripts/setup.sh)" >&2; missing=1; }
done
[ -d "$DATA" ] || { echo "rd.sh: no data directory $DATA" >&2; missing=1; }
gpcc=()
if [ -n "${TMC3:-}" ]; then
  if [ -x "$TMC3" ]; then
    gpcc=(--tmc3 "$TMC3")
    /usr/bin/python3 -c 'import numpy' 2> /dev/null || { echo "rd.sh: G-PCC rows need python3-numpy" >&2; missing=1; }
  else
    echo "rd.sh: TMC3=$TMC3 is not an executable" >&2; missing=1
  fi
fi
[ "$missing" -eq 0 ] || exit 1

mkdir -p "$OUT"
rm -f "$OUT/rows.jsonl" "$OUT/alphabets.jsonl"
draco_version="$(dpkg-query -W -f='${Version}' draco 2>/dev/null || echo unknown)"
echo "rd.sh: build $BUILD_DIR, lex3d $LEX3D ($("$LEX3D" --version 2>/dev/null | head -1)), data $DATA, datasets ${DATASETS[*]}, results in $OUT (draco $draco_version, G-PCC ${TMC3:-not run})"
start=$(date +%s)
/usr/bin/python3 bench/rd.py --build "$BUILD_DIR" --data "$DATA" --out "$OUT" --lex3d "$LEX3D" ${gpcc[@]+"${gpcc[@]}"} ${flags[@]+"${flags[@]}"} "${DATASETS[@]}"
/usr/bin/python3 bench/rd_report.py "$OUT"
echo "rd.sh: wall time $(( $(date +%s) - start )) s"
