#!/usr/bin/env bash
# What `lex3d compress --fast` costs and saves: for each input and bound, the bytes and the
# CPU time (user + system of the whole command, one thread, positions only) of the default
# encoding and of --fast, and the files' sizes compared.
#
# Usage: bench/fast.sh [--lex3d BIN] [--errors "0.005 0.014 ..."] INPUT...
#   INPUT  any input compress reads (a capture's turns are summed)
# Prints one line an input and bound:
#   input E_mm points bytes_default bytes_fast fast/default cpu_s_default cpu_s_fast coding_default coding_fast
# then the median and the extremes of fast/default over every line.
set -euo pipefail
cd "$(dirname "$0")/.."
LEX3D=build/lex3d
ERRORS="0.005 0.014 0.035 0.1"
while [ $# -gt 0 ]; do
  case "$1" in
    --lex3d) LEX3D="$2"; shift 2 ;;
    --errors) ERRORS="$2"; shift 2 ;;
    *) break ;;
  esac
done
[ $# -gt 0 ] || { echo "usage: bench/fast.sh [--lex3d BIN] [--errors \"E...\"] INPUT..." >&2; exit 1; }
[ -x "$LEX3D" ] || { echo "fast.sh: $LEX3D missing (build first)" >&2; exit 1; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
run() {  # run ARGS...: prints "bytes points cpu_s codings"
  rm -rf "$tmp/o" && mkdir "$tmp/o"
  /usr/bin/time -f "%U %S" -o "$tmp/time" "$LEX3D" compress "$@" -o "$tmp/o/m.lex3d" --json --threads 1 \
    --drop-attributes --quiet > "$tmp/out.json"
  /usr/bin/python3 - "$tmp/out.json" "$tmp/time" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
u, s = (float(x) for x in open(sys.argv[2]).read().split()[-2:])
codings = sorted({f["residual"]["coding"] for f in d["files"]})
print(d["total_bytes"], sum(f["points"] for f in d["files"]), "%.3f" % (u + s), ",".join(codings))
EOF
}
printf "%-44s %5s %8s %9s %9s %7s %7s %7s %s\n" input E_mm points default_B fast_B ratio cpu_def cpu_fast "coding (default / fast)"
for input in "$@"; do
  for e in $ERRORS; do
    read -r b0 n t0 c0 < <(run "$input" --max-error "$e")
    read -r b1 _ t1 c1 < <(run "$input" --max-error "$e" --fast)
    awk -v s="$input" -v e="$e" -v n="$n" -v b0="$b0" -v b1="$b1" -v t0="$t0" -v t1="$t1" -v c0="$c0" -v c1="$c1" \
      'BEGIN { if (length(s) > 44) s = "..." substr(s, length(s) - 40);
               printf "%-44s %5.0f %8d %9d %9d %7.4f %7.3f %7.3f %s / %s\n", s, e * 1000, n, b0, b1, b1 / b0, t0, t1, c0, c1 }'
  done
done | tee "$tmp/lines"
sort -k6 -g "$tmp/lines" | awk '{ r[NR] = $6; t0 += $7; t1 += $8 }
  END { if (NR == 0) exit; m = (NR % 2) ? r[(NR + 1) / 2] : (r[NR / 2] + r[NR / 2 + 1]) / 2;
        printf "fast/default bytes over %d codings: median %.4f, min %.4f, max %.4f; CPU %.1f s -> %.1f s (%.2f)\n",
               NR, m, r[1], r[NR], t0, t1, t1 / t0 }'
