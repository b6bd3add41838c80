#!/usr/bin/env bash
# What the per-point times of raw captures cost in a model file: every Ouster and Velodyne
# capture under DATA compressed at E (one thread) with its times and without them
# (--drop-field time), and its turns as a driver writes them (`lex3d convert` to PLY:
# unorganised, ring and time kept); prints, per capture, its turns and points, the file
# sizes, the time field's bytes and bits a point (formats/model.md §2.10, method 6).
# Usage: [DATA=../shared/data] bench/capture_times.sh [--max-error E] [--lex3d BIN]
set -euo pipefail
cd "$(dirname "$0")/.."
LEX3D=${BUILD_DIR:-build}/lex3d
DATA=${DATA:-../shared/data}
E=0.014
while [ $# -gt 0 ]; do
  case "$1" in
    --max-error) E="$2"; shift ;;
    --lex3d) LEX3D="$2"; shift ;;
    -h|--help) sed -n '2,6p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "capture_times.sh: unknown option $1" >&2; exit 1 ;;
  esac
  shift
done
[ -x "$LEX3D" ] || { echo "capture_times.sh: no lex3d binary at $LEX3D (build it, or give --lex3d)" >&2; exit 1; }
captures=()
for f in "$DATA"/ouster/*.pcap "$DATA"/velodyne/*.pcap; do [ -f "$f" ] && captures+=("$f"); done
[ ${#captures[@]} -gt 0 ] || { echo "capture_times.sh: no captures under $DATA/ouster or $DATA/velodyne" >&2; exit 1; }
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
echo "| capture | turns | points | file without times | with times | time bytes | bits a point | as unorganised PLY | its time bytes |"
echo "|---|---|---|---|---|---|---|---|---|"
for f in "${captures[@]}"; do
  "$LEX3D" compress "$f" -o "$work/with.lex3dm" --max-error "$E" --threads 1 --json > "$work/with.json"
  "$LEX3D" compress "$f" -o "$work/without.lex3dm" --max-error "$E" --threads 1 --drop-field time --json > "$work/without.json"
  rm -f "$work"/turn*.ply
  "$LEX3D" convert "$f" "$work/turn.ply" > /dev/null
  "$LEX3D" compress "$work"/turn*.ply -o "$work/ply.lex3dm" --max-error "$E" --threads 1 --json > "$work/ply.json" 2> /dev/null
  /usr/bin/python3 - "$f" "$work/with.json" "$work/without.json" "$work/ply.json" <<'PY'
import json, os, sys
with_t = json.load(open(sys.argv[2]))["files"]
without = json.load(open(sys.argv[3]))["files"]
ply = json.load(open(sys.argv[4]))["files"]
points = sum(x["points"] for x in with_t)
a = sum(x["bytes"] for x in with_t)
b = sum(x["bytes"] for x in without)
t = sum(f["bytes"] for x in with_t for f in x.get("attributes", []) if f["name"] == "time")
p = sum(x["bytes"] for x in ply)
pt = sum(f["bytes"] for x in ply for f in x.get("attributes", []) if f["name"] == "time")
print(f"| {os.path.basename(sys.argv[1])} | {len(with_t)} | {points:,} | {b:,} | {a:,} (+{100 * (a - b) / b:.2f} %) "
      f"| {t:,} | {8 * t / points:.3f} | {p:,} | {pt:,} |")
PY
done
