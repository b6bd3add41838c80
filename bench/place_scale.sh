#!/usr/bin/env bash
# The place database at map scale: databases of 100, 1,000 and 5,000 entries made from the
# balm scans, and per size the database load time, the peak memory of a `place query` process,
# the median / 95th-percentile query time split into preparation (features + words of the
# query scan), retrieval (tf-idf over the inverted index) and verification (decoding the
# candidates' entries + geometric check), recall of the true revisits, and bytes a scan;
# then a projection to 1e5 and 1e6 entries from the measured per-entry costs.
#
# Protocol: the base database holds the balm scans of the first 30 s (files 000000-000058,
# built with `place build`, alphabet learned on 5 of them); the queries are the scans from
# 50 s on (000100-000176), so every query is at least 20 s after any base scan. A query is a
# true revisit when a base scan's sensor lies within 8 m (planar; balm has no pair of these
# within 4 m); queries reject transforms that put the sensors more than 8 m apart
# (--max-distance 8, as `place eval --radius 8`). An accepted match is right when its
# transform is within 1 m and 5 degrees of the ground truth (from the poses) and its sensor
# within 8 m; the median pose error of right matches is printed. Larger databases add
# perturbed copies of the base entries (lex3d_place_scale_db: a random rigid motion of the
# scan frame - any rotation, +-20 m, +-2 m - and 3 % dropout of word instances, features and
# coarse-image pixels); the base entries, and so the true revisits, are kept unmodified. A
# copy shows its place from another frame, so a match to a copy of a base scan within 4 m is
# a right place too; both counts are printed.
# The base database carries a recognition vocabulary learned on its own scans
# (--vocabulary-words 4096; the tree stops splitting where a child would get fewer than 2
# descriptors). The first stage is then measured for each method (--retrieval tfidf-alphabet,
# tfidf, fabmap): for every query with a true revisit, the rank among the first 50 retrieved
# entries of (a) the first entry whose sensor lies within 8 m (a right place: an unmodified
# base scan or a copy, which verification can confirm from its other frame), printed with the
# rank a random order would give, and (b) the first entry of the nearest base scan (itself or
# one of its copies); recall@K for K = 1...50, the retrieval time, and the final recall of the
# whole query (8 candidates verified) per method. A PNG of recall@K goes to PNG_DIR when set.
# Usage: bench/place_scale.sh [BUILD_DIR] [SIZES...]   (default: build, 100 1000 5000)
#        PNG_DIR=dir bench/place_scale.sh ...   also writes dir/place_scale_recall.png
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${1:-$root/build}"
shift || true
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(100 1000 5000)
data="$root/../shared/data/balm"
[ -f "$data/poses.txt" ] || { echo "needs $data" >&2; exit 1; }
[ -x "$build/bench/lex3d_place_scale_db" ] || { echo "needs $build/bench/lex3d_place_scale_db (cmake --build $build --target lex3d_place_scale_db)" >&2; exit 1; }
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
echo "load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"

mapfile -t frames < "$data/frames.txt"
base=(); queries=(); : > "$out/base_poses.txt"; : > "$out/query_poses.txt"
for i in "${!frames[@]}"; do
  f="${frames[$i]}"; n=$((10#${f%.bin}))
  pose="$(sed -n "$((i + 1))p" "$data/poses.txt")"
  if [ "$n" -lt 60 ]; then base+=("$data/$f"); echo "$pose" >> "$out/base_poses.txt"; fi
  if [ "$n" -ge 100 ]; then queries+=("$data/$f"); echo "$pose" >> "$out/query_poses.txt"; fi
done
echo "base scans: ${#base[@]}, queries: ${#queries[@]}"
t0=$(date +%s%N)
"$build/lex3d" place build "$out/base.lex3dp" "${base[@]}" --poses "$out/base_poses.txt" --learn-scans 5 \
  --vocabulary-words 4096 > "$out/build.txt" 2> "$out/build_err.txt"
grep -a "recognition vocabulary" "$out/build_err.txt" | tr '\r' '\n' | grep -a "recognition vocabulary" | tail -1
echo "built base database in $(( ($(date +%s%N) - t0) / 1000000 )) ms: $(cat "$out/build.txt")"
head -10 "$out/query_poses.txt" > "$out/query10_poses.txt"

for n in "${sizes[@]}"; do
  t0=$(date +%s%N)
  "$build/bench/lex3d_place_scale_db" "$out/base.lex3dp" "$n" 7 0.03 "$out/db$n.lex3dp" "$out/sensors$n.txt"
  mk=$(( ($(date +%s%N) - t0) / 1000000 ))
  # All queries in one process (one database load), JSON Lines; peak memory by time -v.
  /usr/bin/time -v "$build/lex3d" place query "$out/db$n.lex3dp" "${queries[@]}" --poses "$out/query_poses.txt" \
    --json --top 1 --threads 1 --max-distance 8 > "$out/q$n.jsonl" 2> "$out/time$n.txt"
  # The whole process for 10 scans.
  /usr/bin/time -v "$build/lex3d" place query "$out/db$n.lex3dp" "${queries[@]:0:10}" --poses "$out/query10_poses.txt" \
    --json --top 1 --threads 1 --max-distance 8 > /dev/null 2> "$out/time10_$n.txt"
  /usr/bin/python3 - "$n" "$out" "$mk" "$data/poses.txt" <<'PY'
import json, math, sys, os, re
n, out, mk, poses_path = int(sys.argv[1]), sys.argv[2], float(sys.argv[3]) / 1000.0, sys.argv[4]
qs = [json.loads(l) for l in open(f"{out}/q{n}.jsonl")]
ent = {}
for l in open(f"{out}/sensors{n}.txt"):
    p = l.split()
    ent[p[0]] = (float(p[1]), float(p[2]))
frames = [l.strip() for l in open(os.path.join(os.path.dirname(poses_path), "frames.txt")) if l.strip()]
poses = [list(map(float, l.split())) for l in open(poses_path) if l.strip()]
qpos = {f[:-4]: (poses[i][3], poses[i][7]) for i, f in enumerate(frames)}
def dist(a, b): return math.hypot(a[0] - b[0], a[1] - b[1])
def timev(path, key):
    for l in open(path):
        if key in l: return l.split(": ", 1)[1].strip()
    return "?"
def secs(s):
    parts = [float(x) for x in s.split(":")]
    return sum(v * 60 ** (len(parts) - 1 - i) for i, v in enumerate(parts))
def pct(v, p):
    v = sorted(v); k = (len(v) - 1) * p; f = math.floor(k); c = min(f + 1, len(v) - 1)
    return v[f] + (v[c] - v[f]) * (k - f)
import numpy as np
T = {}
for l in open(f"{out}/sensors{n}.txt"):
    p = l.split()
    M = np.eye(4); M[:3, :] = np.array(list(map(float, p[4:16]))).reshape(3, 4); T[p[0]] = M
Tq = {}
for i, f in enumerate(frames):
    M = np.eye(4); M[:3, :] = np.array(poses[i]).reshape(3, 4); Tq[f[:-4]] = M
base_names = [k for k in ent if "~" not in k]
pos = tp_base = tp_any = fp = 0
et, er = [], []
for q in qs:
    qp = qpos[q["query"]]
    is_pos = any(dist(qp, ent[b]) <= 8.0 for b in base_names)
    pos += is_pos
    m = q["matches"][0] if q["matches"] else None
    if m and m["accepted"]:
        Tm = np.eye(4); Tm[:3, :] = np.array(m["T_match_query"]).reshape(3, 4)
        D = np.linalg.inv(np.linalg.inv(T[m["scan"]]) @ Tq[q["query"]]) @ Tm
        te = np.linalg.norm(D[:3, 3]); re = math.degrees(math.acos(max(-1, min(1, (np.trace(D[:3, :3]) - 1) / 2))))
        right = dist(qp, ent[m["scan"]]) <= 8.0 and te <= 1.0 and re <= 5.0
        if right and is_pos:
            tp_any += 1
            tp_base += "~" not in m["scan"]
            et.append(te); er.append(re)
        elif not right:
            fp += 1
size = os.path.getsize(f"{out}/db{n}.lex3dp")
rss_kb = int(timev(f"{out}/time{n}.txt", "Maximum resident set size"))
wall10 = secs(timev(f"{out}/time10_{n}.txt", "Elapsed (wall clock)"))
rss10 = int(timev(f"{out}/time10_{n}.txt", "Maximum resident set size"))
def col(k): return [q[k] for q in qs]
print(f"== {n} entries: {size/1e6:.1f} MB ({size/n/1024:.1f} KB a scan), made in {mk:.1f} s ==")
print(f"  load (open + index check): {qs[0]['database_open_ms']:.1f} ms")
print(f"  peak memory, {len(qs)} queries in one process: {rss_kb/1024:.0f} MB (= {rss_kb*1024/size:.2f} x file size; target <= 1.5 x file + 100 MB = {(1.5*size/1e6+100):.0f} MB)")
print(f"  whole process, 10 queries: {wall10:.2f} s, peak {rss10/1024:.0f} MB")
for k in ("prepare_ms", "retrieval_ms", "decode_ms", "verification_ms"):
    v = col(k); print(f"  {k:16s} median {pct(v,0.5):8.1f}  p95 {pct(v,0.95):8.1f}")
for k in ("prepare_cpu_ms", "query_cpu_ms"):
    v = col(k); print(f"  {k:16s} median {pct(v,0.5):8.1f}  p95 {pct(v,0.95):8.1f}   (process CPU time)")
v = [a + b for a, b in zip(col("retrieval_ms"), col("verification_ms"))]
print(f"  {'query (ret+ver)':16s} median {pct(v,0.5):8.1f}  p95 {pct(v,0.95):8.1f}   (1 thread; verification includes decode)")
print(f"  true revisits (base scan within 8 m): {pos}; found: {tp_base} as the unmodified scan, {tp_any} as any right place "
      f"(recall {tp_any/max(pos,1):.3f}); accepted wrong: {fp}; median pose error of right matches "
      f"{np.median(et) if et else float('nan'):.3f} m, {np.median(er) if er else float('nan'):.2f} deg")
cpu10 = float(timev(f"{out}/time10_{n}.txt", "User time")) + float(timev(f"{out}/time10_{n}.txt", "System time"))
print(f"  whole process, 10 queries: CPU {cpu10:.2f} s (user + system)")
with open(f"{out}/summary.txt", "a") as s:
    s.write(f"{n} {size} {qs[0]['database_open_ms']} {rss_kb} {pct(col('retrieval_ms'),0.5)} {pct(col('verification_ms'),0.5)} {pct(col('prepare_ms'),0.5)}\n")
PY
  # The first stage of each method: its 50 best entries a query (and the whole query's answer).
  for m in tfidf-alphabet tfidf fabmap; do
    "$build/lex3d" place query "$out/db$n.lex3dp" "${queries[@]}" --poses "$out/query_poses.txt" \
      --json --top 1 --threads 1 --max-distance 8 --retrieval "$m" --list-retrieved 50 > "$out/rank${n}_$m.jsonl"
  done
done

/usr/bin/python3 - "$out" "$data/poses.txt" "${PNG_DIR:-}" "${sizes[@]}" <<'PY'
import json, math, os, sys
import numpy as np
out, poses_path, png_dir, sizes = sys.argv[1], sys.argv[2], sys.argv[3], [int(x) for x in sys.argv[4:]]
frames = [l.strip() for l in open(os.path.join(os.path.dirname(poses_path), "frames.txt")) if l.strip()]
poses = [list(map(float, l.split())) for l in open(poses_path) if l.strip()]
qpos = {f[:-4]: (poses[i][3], poses[i][7]) for i, f in enumerate(frames)}
Tq = {}
for i, f in enumerate(frames):
    M = np.eye(4); M[:3, :] = np.array(poses[i]).reshape(3, 4); Tq[f[:-4]] = M
methods = ["tfidf-alphabet", "tfidf", "fabmap"]
Ks = list(range(1, 51))
curves = {}
print("== FIRST STAGE: recall@K of the true revisits (R = 8 m), per method ==")
print("  (a) place: first retrieved entry within 8 m (chance: what a random order gives);"
      " (b) nearest: first entry of the nearest base scan or its copies")
print(f"  {'entries':>7s} {'method':14s} {'revisits':>8s}  " + "  ".join(f"{'@'+str(k):>6s}" for k in (1, 2, 4, 8, 16, 32, 50))
      + "   retrieval ms median/p95   final recall (accepted right)")
for n in sizes:
    ent, T = {}, {}
    for l in open(f"{out}/sensors{n}.txt"):
        p = l.split(); ent[p[0]] = (float(p[1]), float(p[2]))
        M = np.eye(4); M[:3, :] = np.array(list(map(float, p[4:16]))).reshape(3, 4); T[p[0]] = M
    base = [k for k in ent if "~" not in k]
    for m in methods:
        qs = [json.loads(l) for l in open(f"{out}/rank{n}_{m}.jsonl")]
        ra, rb, chance, tp = [], [], [], 0
        for q in qs:
            qp = qpos[q["query"]]
            d = lambda s: math.hypot(qp[0] - ent[s][0], qp[1] - ent[s][1])
            good = [b for b in base if d(b) <= 8.0]
            if not good: continue
            nearest = min(good, key=d)
            ra.append(next((i + 1 for i, s in enumerate(q["retrieved"]) if d(s) <= 8.0), None))
            rb.append(next((i + 1 for i, s in enumerate(q["retrieved"]) if s.split("~")[0] == nearest), None))
            f = sum(1 for s in ent if d(s) <= 8.0) / len(ent)
            chance.append([1 - (1 - f) ** k for k in Ks])
            mm = q["matches"][0] if q["matches"] else None
            if mm and mm["accepted"]:
                Tm = np.eye(4); Tm[:3, :] = np.array(mm["T_match_query"]).reshape(3, 4)
                D = np.linalg.inv(np.linalg.inv(T[mm["scan"]]) @ Tq[q["query"]]) @ Tm
                te = np.linalg.norm(D[:3, 3]); re = math.degrees(math.acos(max(-1, min(1, (np.trace(D[:3, :3]) - 1) / 2))))
                tp += d(mm["scan"]) <= 8.0 and te <= 1.0 and re <= 5.0
        nr = max(len(ra), 1)
        rec = lambda r: [sum(1 for x in r if x is not None and x <= k) / nr for k in Ks]
        ca, cb, cc = rec(ra), rec(rb), list(np.mean(chance, axis=0)) if chance else [0] * len(Ks)
        curves[(n, m)] = (ca, cb, cc)
        rt = sorted(q["retrieval_ms"] for q in qs)
        p95 = rt[min(len(rt) - 1, int(round(0.95 * (len(rt) - 1))))]
        for label, c in (("(a) place", ca), ("(b) nearest", cb)):
            print(f"  {n:7d} {m:14s} {len(ra):8d}  " + "  ".join(f"{c[k-1]:6.3f}" for k in (1, 2, 4, 8, 16, 32, 50))
                  + (f"   {rt[len(rt)//2]:.2f} / {p95:.2f}   {tp}/{len(ra)} = {tp/nr:.3f}" if label == "(a) place" else "") + f"  {label}")
    c = curves[(n, methods[0])][2]
    print(f"  {n:7d} {'chance (a)':14s} {'':8s}  " + "  ".join(f"{c[k-1]:6.3f}" for k in (1, 2, 4, 8, 16, 32, 50)))
if png_dir:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(sizes), figsize=(5 * len(sizes), 4), squeeze=False)
    for ax, n in zip(axes[0], sizes):
        for m, col in zip(methods, ("tab:gray", "tab:blue", "tab:red")):
            ca, cb, cc = curves[(n, m)]
            ax.plot(Ks, ca, color=col, label=f"{m}: place within 8 m")
            ax.plot(Ks, cb, color=col, linestyle="--", label=f"{m}: nearest base scan")
        ax.plot(Ks, curves[(n, methods[0])][2], color="k", linestyle=":", label="chance (place within 8 m)")
        ax.set_title(f"balm, {n} entries")
        ax.set_xlabel("K (candidates of the first stage)")
        ax.set_ylabel("recall@K of the true revisits")
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    path = os.path.join(png_dir, "place_scale_recall.png")
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")
PY

/usr/bin/python3 - "$out/summary.txt" <<'PY'
import sys
rows = [list(map(float, l.split())) for l in open(sys.argv[1])]
if len(rows) < 2:
    print("projection needs two sizes"); sys.exit(0)
a, b = rows[0], rows[-1]
dn = b[0] - a[0]
per = lambda i: (b[i] - a[i]) / dn
print("== PROJECTION (not measured): linear in entries from the smallest and largest sizes above ==")
print(f"  per entry: {per(1)/1024:.1f} KB on disk, {per(2)*1000:.2f} us of load, {per(3):.1f} KB of peak memory, "
      f"{per(4)*1000:.2f} us of retrieval; verification is per candidate (top-k), not per entry")
for N in (1e5, 1e6):
    f = lambda i: b[i] + per(i) * (N - b[0])
    print(f"  {N:.0e} entries: file {f(1)/1e9:.2f} GB, load {f(2)/1000:.2f} s, peak memory {f(3)/1024/1024:.2f} GB, "
          f"retrieval {f(4):.0f} ms, verification ~{b[5]:.0f} ms, preparation ~{b[6]:.0f} ms")
PY
