#!/usr/bin/env bash
# The sensor-rate goal on one core: encode <= 100 ms and decode <= 30 ms a scan of about
# 130k points (positions only, E = 14 mm by default). For each scan, the default encoding,
# `--fast` and the decoding of the fast file are run RUNS times in turn (A B C A B C ...,
# so that a drift of the machine's speed touches all three alike), each as a whole process
# (start-up and reading included) on one thread; prints the median, minimum and maximum
# wall milliseconds of each, and the file sizes.
# With CALLGRIND=1 (and valgrind installed) also the instructions of one run of each,
# which, unlike times, do not move with the machine's load.
#
# Usage: bench/encode_speed.sh [--lex3d BIN] [--runs N] [--error E] [--threads T] [--attributes] [SCAN...]
#   SCAN          default: ../shared/data/kitti00/000000.bin and 000005.bin
#   --attributes  keep the scans' attributes (the command's default) instead of positions only
set -euo pipefail
cd "$(dirname "$0")/.."
LEX3D=build/lex3d
RUNS=11
E=0.014
THREADS=1
KEEP=(--drop-attributes)
while [ $# -gt 0 ]; do
  case "$1" in
    --lex3d) LEX3D="$2"; shift 2 ;;
    --runs) RUNS="$2"; shift 2 ;;
    --error) E="$2"; shift 2 ;;
    --threads) THREADS="$2"; shift 2 ;;
    --attributes) KEEP=(); shift ;;
    -*) echo "encode_speed.sh: unknown option $1" >&2; exit 1 ;;
    *) break ;;
  esac
done
[ -x "$LEX3D" ] || { echo "encode_speed.sh: $LEX3D missing (build first)" >&2; exit 1; }
[[ "$RUNS" =~ ^[1-9][0-9]*$ ]] || { echo "encode_speed.sh: --runs needs a positive number" >&2; exit 1; }
scans=("$@")
if [ ${#scans[@]} -eq 0 ]; then
  for k in 000000 000005; do
    [ -f "../shared/data/kitti00/$k.bin" ] && scans+=("../shared/data/kitti00/$k.bin")
  done
fi
[ ${#scans[@]} -gt 0 ] || { echo "encode_speed.sh: no scans given and none under ../shared/data/kitti00" >&2; exit 1; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
echo "load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores; $RUNS runs each, E = $E m, --threads $THREADS, $([ ${#KEEP[@]} -eq 0 ] && echo "attributes kept" || echo "positions only")"

# timed NAME ARGS...: one whole-process run, appending its wall milliseconds to $tmp/NAME
timed() {
  local name="$1"; shift
  local t0 t1
  t0=$(date +%s%N)
  "$@" > /dev/null 2>&1 || { echo "encode_speed.sh: failed: $*" >&2; exit 1; }
  t1=$(date +%s%N)
  awk -v w=$(( (t1 - t0) / 1000 )) 'BEGIN { printf "%.1f\n", w / 1000 }' >> "$tmp/$name"
}

printf "%-34s %-8s %9s %9s %9s %9s\n" scan run median_ms min_ms max_ms bytes
for scan in "${scans[@]}"; do
  rm -f "$tmp/default" "$tmp/fast" "$tmp/decode"
  common=(--max-error "$E" ${KEEP[@]+"${KEEP[@]}"} --threads "$THREADS" --quiet)
  for _ in $(seq "$RUNS"); do
    timed default "$LEX3D" compress "$scan" -o "$tmp/d.lex3dm" "${common[@]}"
    timed fast "$LEX3D" compress "$scan" -o "$tmp/f.lex3dm" "${common[@]}" --fast
    timed decode "$LEX3D" decompress "$tmp/f.lex3dm" -o "$tmp/out.bin" --threads "$THREADS" --quiet
  done
  for name in default fast decode; do
    case "$name" in
      default) bytes=$(stat -c %s "$tmp/d.lex3dm") ;;
      fast) bytes=$(stat -c %s "$tmp/f.lex3dm") ;;
      decode) bytes=- ;;
    esac
    sort -n "$tmp/$name" | awk -v s="$(basename "$(dirname "$scan")")/$(basename "$scan")" -v n="$name" -v b="$bytes" '
      { w[NR] = $1 }
      END { m = (NR % 2) ? w[(NR + 1) / 2] : (w[NR / 2] + w[NR / 2 + 1]) / 2
            printf "%-34s %-8s %9.1f %9.1f %9.1f %9s\n", s, n, m, w[1], w[NR], b }'
  done
  if [ "${CALLGRIND:-0}" = 1 ] && command -v valgrind > /dev/null; then
    for name in default fast decode; do
      case "$name" in
        default) cmd=("$LEX3D" compress "$scan" -o "$tmp/d2.lex3dm" "${common[@]}") ;;
        fast) cmd=("$LEX3D" compress "$scan" -o "$tmp/f2.lex3dm" "${common[@]}" --fast) ;;
        decode) cmd=("$LEX3D" decompress "$tmp/f.lex3dm" -o "$tmp/out2.bin" --threads "$THREADS" --quiet) ;;
      esac
      valgrind --tool=callgrind --callgrind-out-file="$tmp/cg" "${cmd[@]}" > /dev/null 2> "$tmp/cg.log"
      printf "%-34s %-8s %s instructions\n" "" "$name" "$(grep -o 'refs: *[0-9,]*' "$tmp/cg.log" | tr -dc '0-9,')"
    done
  fi
done
echo "goal (one core): encode <= 100 ms, decode <= 30 ms a 130k-point scan"
