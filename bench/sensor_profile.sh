#!/usr/bin/env bash
# Bits per point of the re-sampled sensors (bench/resample_sets.sh) with the laser table given
# as a sensor profile (`lex3d compress --sensor OUT/<sensor>/table.json`) against the table
# estimated from the points, at E = 5, 14 and 35 mm; and the CPU time of each encoding
# (user + system of the whole command, one thread).
#
# Usage: bench/sensor_profile.sh [--lex3d BIN] [SETS_DIR] [SCAN_NAME...]
#   SETS_DIR   what resample_sets.sh wrote (default out/resampled)
#   SCAN_NAME  scans of each sensor to code (default kitti00_000000 os1_128_000)
# Prints one line a sensor, scan and bound:
#   sensor scan E points bytes_estimated bytes_profile bpp_estimated bpp_profile cpu_s_estimated cpu_s_profile coding_estimated coding_profile
set -euo pipefail
cd "$(dirname "$0")/.."
LEX3D=build/lex3d
if [ "${1:-}" = "--lex3d" ]; then LEX3D="$2"; shift 2; fi
SETS="${1:-out/resampled}"
shift || true
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(kitti00_000000 os1_128_000)
[ -x "$LEX3D" ] || { echo "sensor_profile.sh: $LEX3D missing (build first)" >&2; exit 1; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
run() {  # run OUT.json ARGS...: compress with --json; prints "bytes points cpu_s coding"
  local out="$1"
  shift
  /usr/bin/time -f "%U %S" -o "$tmp/time" "$LEX3D" compress "$@" -o "$tmp/m.lex3dm" --json --threads 1 > "$out"
  /usr/bin/python3 - "$out" "$tmp/time" <<'EOF'
import json, sys
f = json.load(open(sys.argv[1]))["files"][0]
u, s = (float(x) for x in open(sys.argv[2]).read().split()[-2:])
print(f["bytes"], f["points"], "%.2f" % (u + s), f["residual"]["coding"])
EOF
}
printf "%-36s %-16s %5s %7s %8s %8s %6s %6s %5s %5s %s\n" sensor scan E_mm points est_B prof_B est_bpp prof_bpp est_s prof_s "coding (est / profile)"
for dir in "$SETS"/*/; do
  sensor="$(basename "$dir")"
  table="$dir/table.json"
  [ -f "$table" ] || continue
  for name in "${names[@]}"; do
    scan="$dir/$name.bin"
    [ -f "$scan" ] || continue
    for e in 0.005 0.014 0.035; do
      read -r b0 n t0 c0 < <(run "$tmp/a.json" "$scan" --max-error "$e")
      read -r b1 _ t1 c1 < <(run "$tmp/b.json" "$scan" --max-error "$e" --sensor "$table")
      awk -v s="$sensor" -v k="$name" -v e="$e" -v n="$n" -v b0="$b0" -v b1="$b1" -v t0="$t0" -v t1="$t1" -v c0="$c0" -v c1="$c1" \
        'BEGIN { printf "%-36s %-16s %5.0f %7d %8d %8d %6.2f %6.2f %5.2f %5.2f %s / %s\n", s, k, e * 1000, n, b0, b1, 8 * b0 / n, 8 * b1 / n, t0, t1, c0, c1 }'
    done
  done
done
