#!/usr/bin/env bash
# The two place descriptors side by side (`--descriptor patch|vdlsd`), same spots, same protocol:
# 1. repeatability under re-sampling (lex3d_bench_descriptors): the KITTI sample against itself
#    turned by a quarter and half an azimuth pixel, and pairs of consecutive balm scans (their
#    poses give the transform); matching rate = share of spots whose nearest descriptor in the
#    other scan is the same spot's, and the share that also passes the 0.8 ratio test;
#    CPU time to describe one scan's 160 spots (one thread);
# 2. place recognition on balm (bench/place.sh protocol: every scan against the scans at least
#    20 s older, true within 4 m and 8 m): first-stage recall (a true revisit among the 8
#    candidates), recall at 100 % precision, accepted with a wrong transform, median pose error,
#    with the default first stage (tf-idf over the alphabet's words, the same for both
#    descriptors) and with a recognition vocabulary learned on each descriptor
#    (`--vocabulary-words 4096 --retrieval tfidf`);
# 3. the CPU time to describe a scan for a query (place query's prepare_cpu_ms, 10 balm scans).
# Usage: bench/descriptors.sh [BUILD_DIR]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$root/build}"
bench="$build/bench/lex3d_bench_descriptors"
data="$root/../shared/data/balm"
[ -x "$bench" ] || { echo "needs $bench (cmake --build $build --target lex3d_bench_descriptors)" >&2; exit 1; }
[ -f "$data/poses.txt" ] || { echo "needs $data" >&2; exit 1; }
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
echo "load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"

echo "== repeatability under re-sampling =="
"$bench" --turn "$root/samples/kitti00_000000.bin" 0.25 0.5 2>/dev/null
# Consecutive scans (frames.txt order = poses.txt lines) where the sensor moves.
for pair in "20 21" "40 41" "60 61" "80 81"; do
  set -- $pair
  a="$(sed -n "$(($1 + 1))p" "$data/frames.txt")"
  b="$(sed -n "$(($2 + 1))p" "$data/frames.txt")"
  "$bench" --pair "$data/$a" "$data/$b" "$data/poses.txt" "$1" "$2" 2>/dev/null
done

echo "== place recognition on balm =="
for descriptor in patch vdlsd; do
  for radius in 4 8; do
    echo "-- --descriptor $descriptor, radius $radius m, first stage tf-idf over the alphabet's words"
    "$build/lex3d" place eval "$data" --poses "$data/poses.txt" --times "$data/times.txt" --min-gap 20 \
      --radius "$radius" --descriptor "$descriptor" --cache "$out/$descriptor.lex3dp" 2>/dev/null |
      grep -E "^descriptor|recall at 100|first stage|accepted|median error"
  done
  for radius in 4 8; do
    echo "-- --descriptor $descriptor, radius $radius m, first stage tf-idf over a vocabulary of its descriptors"
    "$build/lex3d" place eval "$data" --poses "$data/poses.txt" --times "$data/times.txt" --min-gap 20 \
      --radius "$radius" --descriptor "$descriptor" --vocabulary-words 4096 --retrieval tfidf \
      --cache "$out/$descriptor-voc.lex3dp" 2>/dev/null |
      grep -E "^descriptor|recall at 100|first stage|accepted|median error"
  done
done

echo "== time to describe a scan for place recognition (place query --json prepare_cpu_ms, 2 threads; median of 10 balm scans) =="
frames=($(sed -n '1~9p' "$data/frames.txt" | head -10))
for descriptor in patch vdlsd; do
  "$build/lex3d" place build "$out/t-$descriptor.lex3dp" "$data/${frames[0]}" --descriptor "$descriptor" >/dev/null 2>&1
  for f in "${frames[@]}"; do
    "$build/lex3d" place query "$out/t-$descriptor.lex3dp" "$data/$f" --json 2>/dev/null |
      sed -n 's/.*"prepare_cpu_ms":\([0-9.]*\).*/\1/p'
  done | sort -g | awk -v d="$descriptor" '{v[NR] = $1} END {printf "  %-6s prepare CPU median %.0f ms (min %.0f, max %.0f; %d scans)\n", d, (v[5] + v[6]) / 2, v[1], v[NR], NR}'
done
