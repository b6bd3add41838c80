#!/usr/bin/env bash
# Place recognition on the balm revisits (../shared/data/README.md protocol): every scan
# queries the database of the scans recorded at least 20 s earlier; a retrieved scan is a
# true match within 4 m (and 8 m) planar distance. Prints precision/recall at the default
# threshold, recall at 100% precision, accepted matches with a right / wrong transform,
# median relative pose error of accepted true matches, query time (excluding feature
# extraction; wall and CPU, 2 threads) and database size per scan.
# Then, at 8 m, each first stage (--retrieval tfidf-alphabet, tfidf, fabmap; the last two over
# a recognition vocabulary of at most 4,096 words learned on the scans) with the same
# verification: recall at 100 % precision per method.
# Usage: [PNG_DIR=dir] bench/place.sh [BUILD_DIR] [extra `place eval` options, e.g. --threads 1]
#   (default BUILD_DIR: build). The first radius learns the alphabet and prepares the scans
#   and keeps them in a temporary place database (--cache) that the second radius reuses.
#   PNG_DIR keeps the pictures (precision-recall curve with labelled axes, score matrix) of
#   every run: <run>_pr.png, <run>_confusion.png.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$root/build}"
shift || true
data="$root/../shared/data/balm"
[ -f "$data/poses.txt" ] || { echo "needs $data" >&2; exit 1; }
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
keep_pngs() { [ -z "${PNG_DIR:-}" ] || { mkdir -p "$PNG_DIR" && cp "$out"/*.png "$PNG_DIR"/ 2> /dev/null || true; }; }
echo "load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
for radius in 4 8; do
  echo "== radius ${radius} m, min gap 20 s (transforms implying sensors farther apart than ${radius} m rejected) =="
  "$build/lex3d" place eval "$data" --poses "$data/poses.txt" --times "$data/times.txt" \
    --min-gap 20 --radius "$radius" --png "$out/r$radius" --cache "$out/scans.lex3dp" "$@"
done
# The same without the distance limit: every right transform of scans more than 4 m apart
# then counts as a false positive of the 4 m protocol.
echo "== radius 4 m, min gap 20 s, transforms of any implied distance (--max-distance 0) =="
"$build/lex3d" place eval "$data" --poses "$data/poses.txt" --times "$data/times.txt" \
  --min-gap 20 --radius 4 --max-distance 0 --png "$out/any" --cache "$out/scans.lex3dp" "$@"

# Without poses: each scan's up direction estimated from its own points (--gravity points);
# the poses serve as ground truth only.
for radius in 4 8; do
  echo "== radius ${radius} m, min gap 20 s, up direction from the points (--gravity points) =="
  "$build/lex3d" place eval "$data" --poses "$data/poses.txt" --times "$data/times.txt" \
    --min-gap 20 --radius "$radius" --gravity points --png "$out/p$radius" --cache "$out/points.lex3dp" "$@"
done

# Each first-stage method at 8 m over one recognition vocabulary (the cache keeps the prepared
# scans and the vocabulary; its first run learns them).
for method in tfidf-alphabet tfidf fabmap; do
  echo "== radius 8 m, min gap 20 s, first stage ${method} (vocabulary of at most 4,096 words) =="
  "$build/lex3d" place eval "$data" --poses "$data/poses.txt" --times "$data/times.txt" \
    --min-gap 20 --radius 8 --vocabulary-words 4096 --retrieval "$method" --png "$out/m_$method" \
    --cache "$out/vocabulary.lex3dp" "$@"
done
keep_pngs

# Scan Context on the same scans and protocol (bench/scan_context.py: its published 80 m
# grid, and 40 m, which suits this 18 x 20 m courtyard better), for comparison.
if [ -x /usr/bin/python3 ]; then
  for range in 80 40; do
    echo "== Scan Context, max range ${range} m, min gap 20 s, radius 4 and 8 m =="
    /usr/bin/python3 "$root/bench/scan_context.py" "$data" --min-gap 20 --radius 4 8 --max-range "$range"
  done
fi

# A second sensor: kitti00 (HDL-64E, 10 frames 0.1 s apart), each frame against the frames
# at least 0.25 s older. KITTI's poses are of the left camera; they are turned into lidar
# poses with the nominal axes (lidar x, y, z = camera z, -x, -y; the calibration's ~1 degree
# and few-centimetre offsets are left out, so errors below that are not resolved).
kitti="$root/../shared/data/kitti00"
if [ -f "$kitti/poses.txt" ] && [ -x /usr/bin/python3 ]; then
  mkdir -p "$out/kitti"
  for f in "$kitti"/*.bin; do ln -sf "$f" "$out/kitti/"; done
  cp "$kitti/times.txt" "$out/kitti/"
  /usr/bin/python3 - "$kitti/poses.txt" "$out/kitti/poses.txt" <<'PY'
import sys
rows = [list(map(float, l.split())) for l in open(sys.argv[1]) if l.strip()]
A = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]  # camera <- lidar axes
def mul(X, Y): return [[sum(X[i][k] * Y[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
At = [list(r) for r in zip(*A)]
with open(sys.argv[2], "w") as out:
    for r in rows:
        R = [r[0:3], r[4:7], r[8:11]]
        t = [r[3], r[7], r[11]]
        Rl = mul(mul(At, R), A)
        tl = [sum(At[i][k] * t[k] for k in range(3)) for i in range(3)]
        out.write(" ".join(f"{v:.9g}" for i in range(3) for v in Rl[i] + [tl[i]]) + "\n")
PY
  echo "== kitti00, every frame against the frames at least 0.25 s older (radius 100 m: every frame counts) =="
  "$build/lex3d" place eval "$out/kitti" --poses "$out/kitti/poses.txt" --times "$out/kitti/times.txt" \
    --min-gap 0.25 --radius 100 --png "$out/kitti_r" "$@"
fi
keep_pngs
