#!/usr/bin/env bash
# Where compress spends its time with a known alphabet, on one core: an alphabet is learned
# on the first scan of each sequence, then every other scan is compressed with it
# (--threads 1), decompressed and compared with its input. Prints, per sequence, the median
# of each stage (the command's --json timings_ms), the whole command's own time, the
# process wall time, bits per point, D1 PSNR and inliers.
# Usage: bench/compress_stages.sh [BUILD_DIR] [DATA_DIR] [SEQUENCE...]
#   (defaults: build, ../shared/data, kitti00 balm). Needs a Release build.
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/sequence_args.sh
echo "load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
for seq in "${SEQS[@]}"; do
  scans=("$DATA/$seq"/[0-9]*.bin)
  [ ${#scans[@]} -ge 2 ] || { echo "$seq: needs at least two scans in $DATA/$seq" >&2; exit 1; }
  "$LEX3D" learn "${scans[0]}" -o "$WORK/$seq.lex3da" --json > /dev/null
  for s in "${scans[@]:1}"; do
    b="$(basename "$s" .bin)"
    start=$(date +%s%N)
    "$LEX3D" compress "$s" --alphabet "$WORK/$seq.lex3da" -o "$WORK/m.lex3dm" --max-error none --threads 1 --json > "$WORK/c_$b.json"
    end=$(date +%s%N)
    echo "{\"wall_ms\": $(( (end - start) / 1000000 ))}" > "$WORK/w_$b.json"
    "$LEX3D" decompress "$WORK/m.lex3dm" --alphabet "$WORK/$seq.lex3da" -o "$WORK/d.ply" --reference "$s" --json \
      > "$WORK/d_$b.json"
  done
  /usr/bin/python3 - "$WORK" "$seq" <<'PY'
import glob, json, os, statistics, sys
work, seq = sys.argv[1], sys.argv[2]
keys = sorted(os.path.basename(f)[2:-5] for f in glob.glob(os.path.join(work, "c_*.json")))
c = [json.load(open(os.path.join(work, f"c_{k}.json"))) for k in keys]
w = [json.load(open(os.path.join(work, f"w_{k}.json")))["wall_ms"] for k in keys]
d = [json.load(open(os.path.join(work, f"d_{k}.json"))) for k in keys]
med = statistics.median
f0 = [x["files"][0] for x in c]
print(f"## {seq}: {len(keys)} scans compressed with the alphabet of the first, one thread; medians")
print(f"points {med(f['points'] for f in f0):.0f}, features {med(f['features'] for f in f0):.0f}, "
      f"instances {med(f['instances'] for f in f0):.0f}")
print("| stage | ms |\n|---|---|")
print(f"| read | {med(x['read_ms'] for x in c):.1f} |")
for st in f0[0]["timings_ms"]:
    print(f"| {st} | {med(f['timings_ms'][st] for f in f0):.1f} |")
print(f"| **command (own timer)** | **{med(x['time_ms'] for x in c):.1f}** |")
print(f"| process wall | {med(w):.0f} |")
print(f"\nbits/pt {med(f['bits_per_point'] for f in f0):.3f}, D1 PSNR {med(x['against_reference']['d1_psnr_db'] for x in d):.2f} dB, "
      f"inliers {100 * med(x['against_reference']['inliers'] for x in d):.1f} %\n")
PY
  rm -f "$WORK"/c_*.json "$WORK"/w_*.json "$WORK"/d_*.json
done
