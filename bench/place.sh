#!/usr/bin/env bash
# Place recognition on the balm revisits (../shared/data/README.md protocol): every scan
# queries the database of the scans recorded at least 20 s earlier; a retrieved scan is a
# true match within 4 m (and 8 m) planar distance. Prints precision/recall at the default
# threshold, recall at 100% precision, accepted matches with a right / wrong transform,
# median relative pose error of accepted true matches, query time (excluding feature
# extraction; wall and CPU, 2 threads) and database size per scan.
# Usage: bench/place.sh [BUILD_DIR] [extra `place eval` options, e.g. --threads 1]
#   (default BUILD_DIR: build). The first radius learns the alphabet and prepares the scans
#   and keeps them in a temporary place database (--cache) that the second radius reuses.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$root/build}"
shift || true
data="$root/../shared/data/balm"
[ -f "$data/poses.txt" ] || { echo "needs $data" >&2; exit 1; }
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
echo "load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
for radius in 4 8; do
  echo "== radius ${radius} m, min gap 20 s =="
  "$build/lex3d" place eval "$data" --poses "$data/poses.txt" --times "$data/times.txt" \
    --min-gap 20 --radius "$radius" --png "$out/r$radius" --cache "$out/scans.lex3dp" "$@"
done
