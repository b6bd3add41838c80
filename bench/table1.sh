#!/usr/bin/env bash
# ruhnke2010 Table I on real scans: alphabet size, word radius, word occurrences,
# compression rate (plain and deflated), inliers, outliers and runtime, for one outdoor
# scan, one indoor scan, a 10-scan balm sequence and 10 KITTI scans (one alphabet each
# set). Needs a Release build (scripts/setup.sh) and ../shared/data.
# Usage: bench/table1.sh [BUILD_DIR] [DATA_DIR] [extra lex3d reconstruct options...]
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR="${1:-build}"
DATA="${2:-../shared/data}"
shift $(( $# > 2 ? 2 : $# )) || true
EXTRA=("$@")
LEX3D="$BUILD_DIR/lex3d"
[ -x "$LEX3D" ] || { echo "bench/table1.sh: build $LEX3D first (scripts/setup.sh)" >&2; exit 1; }
[ -d "$DATA/balm" ] || { echo "bench/table1.sh: $DATA/balm is needed" >&2; exit 1; }
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

BALM10=()
for i in 000000 000002 000004 000006 000008 000010 000012 000014 000016 000018; do BALM10+=("$DATA/balm/$i.bin"); done
head -n 10 "$DATA/balm/poses.txt" > "$WORK/balm10_poses.txt"
KITTI10=("$DATA"/kitti00/00000?.bin)

# table TITLE [options...]: the four rows with these lex3d reconstruct options, one table.
table() {
  local title="$1"; shift
  local opts=("$@" "${EXTRA[@]}")
  rm -f "$WORK/order"
  run() {  # name, then lex3d reconstruct arguments
    local name="$1"; shift
    "$LEX3D" reconstruct "$@" -o "$WORK/$name.ply" --json "${opts[@]}" > "$WORK/$name.json"
    echo "$name" >> "$WORK/order"
  }
  run "balm 000000 (one scan)" "$DATA/balm/000000.bin" --poses <(head -n 1 "$DATA/balm/poses.txt")
  run "indoor room_scan1" "$DATA/indoor/room_scan1.pcd"
  run "balm sequence (10 scans)" "${BALM10[@]}" --poses "$WORK/balm10_poses.txt"
  run "kitti00 (10 scans)" "${KITTI10[@]}"
  echo
  echo "$title"
  echo
  /usr/bin/python3 - "$WORK" <<'PY'
import json, sys, os
work = sys.argv[1]
print("| data set | alphabet size | word radius | word occurrences | compression rate | comp. rate (gzip) | inliers | outliers | D1 PSNR | runtime |")
print("|---|---|---|---|---|---|---|---|---|---|")
for name in open(os.path.join(work, "order")).read().splitlines():
    j = json.load(open(os.path.join(work, name + ".json")))
    t = j["total"]
    print(f"| {name} | {j['alphabet_words']} | {j['word_radius_m']:.2f} m | {t['instances']} | "
          f"{100*t['compression_rate']:.1f}% | {100*t['gzip_rate']:.1f}% | {100*t['inliers']:.1f}% | "
          f"{100*t['outliers']:.1f}% | {t['d1_psnr_db']:.1f} dB | {j['timings_ms']['model']/1000:.1f} s |")
PY
}

table "Default parameters (ruhnke2010's pruning rule):"
# Coverage points half a word radius apart (twice as many instances to start from) and
# pruning that keeps the last instance explaining a point within σ: the inlier setting.
table "Dense coverage: --coverage-factor 0.5 --prune-keep-cover" --coverage-factor 0.5 --prune-keep-cover
