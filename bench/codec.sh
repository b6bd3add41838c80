#!/usr/bin/env bash
# Model-file sizes and speed on real sequences: bits per input point with one alphabet
# per scan and with one shared alphabet per sequence (learned on every 10th scan, the
# rest encoded with it: nothing is learned for them), compress time with a known
# alphabet and decompress time, per scan (median). Needs a Release build and
# ../shared/data. Usage: bench/codec.sh [BUILD_DIR] [DATA_DIR] [SEQUENCE...]
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/sequence_args.sh

for seq in "${SEQS[@]}"; do
  rm -f "$WORK"/*.json  # a sequence's figures only (scan names repeat across sequences)
  scans=("$DATA/$seq"/[0-9]*.bin)
  poses=()
  [ "$seq" = balm ] && poses=(--poses "$DATA/balm/poses.txt")
  # One alphabet per scan (embedded in each model file).
  for s in "${scans[@]}"; do
    "$LEX3D" compress "$s" -o "$WORK/own.lex3dm" --max-error none --json > "$WORK/own_$(basename "$s").json"
  done
  # One shared alphabet: learned on every 10th scan, with their poses when known.
  learn=()
  learn_poses="$WORK/learn_poses.txt"
  : > "$learn_poses"
  for i in "${!scans[@]}"; do
    if (( i % 10 == 0 )); then
      learn+=("${scans[$i]}")
      [ "$seq" = balm ] && sed -n "$((i + 1))p" "$DATA/balm/poses.txt" >> "$learn_poses"
    fi
  done
  lp=()
  [ "$seq" = balm ] && lp=(--poses "$learn_poses")
  "$LEX3D" learn "${learn[@]}" "${lp[@]}" -o "$WORK/$seq.lex3da" --json > "$WORK/learn_$seq.json"
  for i in "${!scans[@]}"; do
    s="${scans[$i]}"
    sp=()
    if [ "$seq" = balm ]; then sed -n "$((i + 1))p" "$DATA/balm/poses.txt" > "$WORK/p.txt"; sp=(--poses "$WORK/p.txt"); fi
    "$LEX3D" compress "$s" "${sp[@]}" --alphabet "$WORK/$seq.lex3da" -o "$WORK/shared.lex3dm" --max-error none --json > "$WORK/shared_$(basename "$s").json"
    "$LEX3D" decompress "$WORK/shared.lex3dm" --alphabet "$WORK/$seq.lex3da" -o "$WORK/dec.ply" --reference "$s" --json \
      > "$WORK/dec_$(basename "$s").json"
  done
  /usr/bin/python3 - "$WORK" "$seq" <<'PY'
import glob, json, os, statistics, sys
work, seq = sys.argv[1], sys.argv[2]
def load(prefix):
    return {os.path.basename(f)[len(prefix):-5]: json.load(open(f)) for f in sorted(glob.glob(os.path.join(work, prefix + "*.json")))}
own, shared, dec = load("own_"), load("shared_"), load("dec_")
alpha_bytes = os.path.getsize(os.path.join(work, seq + ".lex3da"))
learned = json.load(open(os.path.join(work, "learn_" + seq + ".json")))
print(f"## {seq}: {len(own)} scans; shared alphabet {learned['words']} words, {alpha_bytes} bytes")
print("| scan | points | bits/pt (own alphabet) | bits/pt (shared, model only) | D1 PSNR | inliers | compress ms | decode+reconstruct ms |")
print("|---|---|---|---|---|---|---|---|")
tot_pts = tot_own = tot_shared = 0
comp, decm, psnr, inl = [], [], [], []
for k in own:
    o, s, d = own[k], shared[k], dec[k]
    pts = o["files"][0]["points"]
    tot_pts += pts; tot_own += o["total_bytes"]; tot_shared += s["files"][0]["bytes"]
    comp.append(s["time_ms"]); decm.append(d["timings_ms"]["decode"] + d["timings_ms"]["reconstruct"])
    psnr.append(d["against_reference"]["d1_psnr_db"]); inl.append(d["against_reference"]["inliers"])
    print(f"| {k} | {pts} | {o['bits_per_point']:.2f} | {8*s['files'][0]['bytes']/pts:.2f} | "
          f"{d['against_reference']['d1_psnr_db']:.1f} dB | {100*d['against_reference']['inliers']:.1f}% | {s['time_ms']:.0f} | {decm[-1]:.1f} |")
print(f"\n{seq} totals: own alphabets {8*tot_own/tot_pts:.2f} bits/pt; shared alphabet {8*(tot_shared+alpha_bytes)/tot_pts:.2f} bits/pt "
      f"(alphabet included once); median D1 PSNR {statistics.median(psnr):.1f} dB, inliers {100*statistics.median(inl):.1f}%; "
      f"median compress (known alphabet, whole command incl. reading) {statistics.median(comp):.0f} ms, "
      f"decode+reconstruct {statistics.median(decm):.1f} ms\n")
PY
done
