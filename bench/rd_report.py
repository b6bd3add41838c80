#!/usr/bin/python3
"""Tables, CSV/JSON and plots from the rows bench/rd.py wrote.

Usage: rd_report.py OUT_DIR [--targets 60 70 75 82.2 86]

Reads OUT_DIR/rows.jsonl (one run a line) and OUT_DIR/alphabets.jsonl, writes
OUT_DIR/rows.csv (every run), OUT_DIR/rd.json (every run, the per-setting medians and
the interpolated rates), OUT_DIR/report.md (the tables, also printed) and
OUT_DIR/rd_<dataset>.png (bits per point against D1 PSNR).

Per dataset and codec setting, every figure is the median over the scans. Rates at equal
quality: for each codec the per-setting medians are reduced to their Pareto front
(no other setting has both a higher PSNR and fewer bits), and bits per point are
interpolated linearly in D1 PSNR between the two front settings around the target;
"—" when no setting reaches the target, "≤ b" when even the cheapest front setting is
above it (b = that setting's bits per point). A last table sets the families side by side at
every target: lex3d (the best of lex3d, lex3d-seq and lex3d-mse), G-PCC octree, G-PCC predictive +
angular, Draco (the better of kd-tree and sequential), PCL octree, and lex3d over the best
standard codec.
"""

import argparse
import csv
import json
import math
import os
import statistics
import sys

CODEC_ORDER = ["lex3d", "lex3d-seq", "lex3d-mse", "gpcc-octree", "gpcc-pred", "draco-kd", "draco-seq", "pcl-octree", "octomap"]
# the side-by-side table: family -> codecs whose best rate it takes
FAMILIES = [("lex3d", ["lex3d", "lex3d-seq", "lex3d-mse"]), ("G-PCC octree", ["gpcc-octree"]),
            ("G-PCC pred+angular", ["gpcc-pred"]), ("Draco", ["draco-kd", "draco-seq"]), ("PCL octree", ["pcl-octree"])]
CSV_COLUMNS = ["dataset", "scan", "codec", "setting", "points", "bytes", "stream_bytes", "shared_bytes", "bpp",
               "d1_psnr_db", "rmse_m", "hausdorff_m", "chamfer_m", "mse_ab", "mse_ba", "coverage_2cm", "coverage_5cm",
               "outliers_2cm", "outliers_5cm", "n_decoded", "encode_ms", "decode_ms", "encode_wall_ms",
               "decode_wall_ms", "encode_peak_kb", "decode_peak_kb", "max_error_m", "words_used", "instances",
               "lasers", "laser_fit_rms_mm", "laser_fit_p95_mm", "error"]


def median(values):
    values = [v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]
    return statistics.median(values) if values else None


def load_jsonl(path):
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def summarise(rows):
    """dataset -> list of per-(codec, setting) medians, in codec order then setting order."""
    groups = {}
    for r in rows:
        if "error" in r:
            continue
        groups.setdefault((r["dataset"], r["codec"], r["setting"]), []).append(r)
    out = {}
    for (ds, codec, setting), rs in groups.items():
        peaks = [max(x for x in (r.get("encode_peak_kb"), r.get("decode_peak_kb")) if x is not None)
                 for r in rs if r.get("encode_peak_kb") is not None or r.get("decode_peak_kb") is not None]
        s = {"codec": codec, "setting": setting, "order": rs[0]["order"], "scans": len(rs)}
        for k in ("bpp", "d1_psnr_db", "rmse_m", "hausdorff_m", "coverage_2cm", "coverage_5cm", "encode_ms",
                  "decode_ms", "encode_wall_ms", "decode_wall_ms", "encode_peak_kb", "decode_peak_kb"):
            s[k] = median([r.get(k) for r in rs])
        s["peak_kb"] = median(peaks)
        s["max_error_m"] = rs[0].get("max_error_m")
        out.setdefault(ds, []).append(s)
    for ds in out:
        out[ds].sort(key=lambda s: (CODEC_ORDER.index(s["codec"]) if s["codec"] in CODEC_ORDER else 99,
                                    s["order"]))
    return out


def pareto(settings):
    """Settings not beaten on both axes, ascending in PSNR (so ascending in bpp)."""
    pts = sorted(((s["d1_psnr_db"], s["bpp"]) for s in settings
                  if s["d1_psnr_db"] is not None and math.isfinite(s["d1_psnr_db"])), key=lambda p: (-p[0], p[1]))
    front, best = [], math.inf
    for q, b in pts:
        if b < best:
            front.append((q, b))
            best = b
    return front[::-1]


def interpolate(settings, target):
    """(kind, bpp): kind 'interp', 'below' (cheapest setting already above target) or 'none'."""
    front = pareto(settings)
    if not front or target > front[-1][0]:
        return "none", None
    if target < front[0][0]:
        return "below", front[0][1]
    for (q0, b0), (q1, b1) in zip(front, front[1:]):
        if q0 <= target <= q1:
            if q1 == q0:
                return "interp", min(b0, b1)
            return "interp", b0 + (b1 - b0) * (target - q0) / (q1 - q0)
    return "interp", front[-1][1]  # target == the only point's PSNR


def fmt(v, spec, scale=1.0):
    if v is None:
        return "—"
    if isinstance(v, float) and math.isinf(v):
        return "∞"
    return format(v * scale, spec)


def tables(summary, alphabets, targets, rows):
    lines = []
    n_scans = {}
    for r in rows:
        n_scans.setdefault(r["dataset"], set()).add(r["scan"])
    interp = {}
    for ds, settings in summary.items():
        alpha = [a for a in alphabets if a["dataset"] == ds]
        lines.append(f"## {ds}: {len(n_scans.get(ds, ()))} scans")
        lines.append("")
        if alpha:
            a = alpha[-1]
            lines.append(f"lex3d-seq alphabet: {a['words']} words, {a['bytes']} bytes, learned once on "
                         f"{', '.join(a['learn_scans'])} in {a['learn_wall_ms'] / 1000:.1f} s; its bytes are shared "
                         f"equally by the {len(n_scans.get(ds, ()))} scans.")
            lines.append("")
        fits = [r for r in rows if r["dataset"] == ds and r.get("laser_fit_rms_mm") is not None]
        if fits:
            per_scan = {r["scan"]: r for r in fits}.values()
            srcs = sorted({r.get("laser_table_source", "estimated") for r in per_scan})
            lines.append(f"G-PCC predictive laser tables ({', '.join(srcs)}; one a scan): "
                         f"{median([r['lasers'] for r in per_scan]):g} lasers (median), fit residual RMS "
                         f"{median([r['laser_fit_rms_mm'] for r in per_scan]):.2f} mm, 95th percentile "
                         f"{median([r['laser_fit_p95_mm'] for r in per_scan]):.2f} mm (medians over the scans).")
            lines.append("")
        picked = {}
        for r in rows:
            if r["dataset"] == ds and r.get("layer_coding") and "error" not in r:
                key = (r["codec"], r["layer_coding"], r.get("lex3d_laser_table") or "")
                picked[key] = picked.get(key, 0) + 1
        if picked:
            lines.append("lex3d residual-layer coding chosen (runs): " + "; ".join(
                f"{c} {lc}{' (table ' + t + ')' if t else ''} ×{k}" for (c, lc, t), k in sorted(picked.items())) + ".")
            lines.append("")
        off = [r for r in rows if r["dataset"] == ds and r.get("lex3d_points") is not None and "error" not in r
               and r["lex3d_points"] != r["points"]]
        if off:
            lines.append(f"NOTE: {len(off)} lex3d runs read a different point count than the reference "
                         f"(e.g. {off[0]['scan']}: {off[0]['lex3d_points']} vs {off[0]['points']}).")
            lines.append("")
        lines.append("| codec | setting | bits/pt | D1 PSNR dB | RMSE mm | Hausdorff m | ≤2 cm % | ≤5 cm % | "
                     "enc ms | dec ms | peak MB |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
        for s in settings:
            lines.append(
                f"| {s['codec']} | {s['setting']} | {fmt(s['bpp'], '.3f')} | {fmt(s['d1_psnr_db'], '.2f')} | "
                f"{fmt(s['rmse_m'], '.2f', 1000)} | {fmt(s['hausdorff_m'], '.4f')} | "
                f"{fmt(s['coverage_2cm'], '.2f', 100)} | {fmt(s['coverage_5cm'], '.2f', 100)} | "
                f"{fmt(s['encode_ms'], '.0f')} | {fmt(s['decode_ms'], '.0f')} | {fmt(s['peak_kb'], '.0f', 1 / 1024)} |")
        lines.append("")
        lines.append("Bits per point at equal D1 PSNR (interpolated on the per-setting medians):")
        lines.append("")
        lines.append("| codec | " + " | ".join(f"{t:g} dB" for t in targets) + " |")
        lines.append("|---|" + "---|" * len(targets))
        codecs = []
        for s in settings:
            if s["codec"] not in codecs:
                codecs.append(s["codec"])
        interp[ds] = {}
        for c in codecs:
            cs = [s for s in settings if s["codec"] == c]
            cells = []
            interp[ds][c] = {}
            for t in targets:
                kind, b = interpolate(cs, t)
                interp[ds][c][f"{t:g}"] = {"kind": kind, "bpp": b}
                cells.append("—" if kind == "none" else (f"≤ {b:.3f}" if kind == "below" else f"{b:.3f}"))
            lines.append(f"| {c} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += side_by_side(interp, targets)
    return "\n".join(lines), interp


def side_by_side(interp, targets):
    """Families at every target: the best interpolated rate of their codecs."""
    def best(cells):
        got = [c for c in cells if c and c["kind"] != "none"]
        if not got:
            return None
        inter = [c for c in got if c["kind"] == "interp"]
        pick = min(inter or got, key=lambda c: c["bpp"])
        return pick

    def show(c):
        if c is None:
            return "—"
        return f"≤ {c['bpp']:.3f}" if c["kind"] == "below" else f"{c['bpp']:.3f}"

    lines = ["## All data sets: bits per point at equal D1 PSNR", "",
             "lex3d = best of lex3d, lex3d-seq and lex3d-mse; Draco = better of kd-tree and sequential; "
             "ratio = lex3d / the best standard codec (G-PCC, Draco, PCL) at that PSNR.", "",
             "| data | codec | " + " | ".join(f"{t:g} dB" for t in targets) + " |",
             "|---|---|" + "---|" * len(targets)]
    for ds, codecs in interp.items():
        fam = {}
        for name, members in FAMILIES:
            fam[name] = [best([codecs.get(m, {}).get(f"{t:g}") for m in members]) for t in targets]
            if all(c is None for c in fam[name]) and not any(m in codecs for m in members):
                continue
            lines.append(f"| {ds} | {name} | " + " | ".join(show(c) for c in fam[name]) + " |")
        ratio = []
        for i in range(len(targets)):
            lex = fam["lex3d"][i]
            std = [fam[n][i] for n, _ in FAMILIES[1:] if fam[n][i] is not None and fam[n][i]["kind"] == "interp"]
            if lex is None or lex["kind"] != "interp" or not std:
                ratio.append("—")
            else:
                ratio.append(f"{lex['bpp'] / min(c['bpp'] for c in std):.2f}")
        lines.append(f"| {ds} | ratio | " + " | ".join(ratio) + " |")
    lines.append("")
    return lines


def plot(summary, targets, out_dir):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("rd_report.py: matplotlib missing (apt-get install python3-matplotlib); no plots", file=sys.stderr)
        return []
    paths = []
    styles = {"lex3d": ("tab:red", "o"), "lex3d-seq": ("tab:purple", "D"), "lex3d-mse": ("tab:pink", "v"), "draco-kd": ("tab:blue", "s"),
              "draco-seq": ("tab:cyan", "v"), "pcl-octree": ("tab:green", "^"), "octomap": ("tab:orange", "x"),
              "gpcc-octree": ("black", "P"), "gpcc-pred": ("tab:brown", "*")}
    for ds, settings in summary.items():
        fig, ax = plt.subplots(figsize=(8, 5.5))
        codecs = []
        for s in settings:
            if s["codec"] not in codecs:
                codecs.append(s["codec"])
        for c in codecs:
            color, marker = styles.get(c, ("black", "."))
            cs = [s for s in settings if s["codec"] == c and s["bpp"] and s["d1_psnr_db"] is not None
                  and math.isfinite(s["d1_psnr_db"])]
            sweep = sorted((s for s in cs if s["order"] > 0), key=lambda s: s["order"])
            # G-PCC predictive: two sweeps (radius/azimuth steps without residual; residual on an
            # integer grid), drawn apart
            parts = [(c, "-", [s for s in sweep if not s["setting"].startswith("res=")]),
                     (c + " (cartesian residual)", ":", [s for s in sweep if s["setting"].startswith("res=")])]
            for label, style, part in parts:
                if part:
                    ax.plot([s["bpp"] for s in part], [s["d1_psnr_db"] for s in part], color=color, marker=marker,
                            label=label, linewidth=1.2, markersize=5, linestyle=style)
            single = [s for s in cs if s["order"] <= 0]
            if single:
                ax.scatter([s["bpp"] for s in single], [s["d1_psnr_db"] for s in single], color=color,
                           marker=marker, s=45, facecolors="none" if sweep else color,
                           label=None if sweep else c)
                if c == "pcl-octree":
                    for s in single:
                        ax.annotate(s["setting"].replace("_RES_", " ").lower(), (s["bpp"], s["d1_psnr_db"]),
                                    fontsize=6, color=color, xytext=(3, 3), textcoords="offset points")
        for t in targets:
            ax.axhline(t, color="grey", linestyle="--", linewidth=0.7)
        ax.set_xscale("log")
        ax.set_xlabel("bits per input point (log)")
        ax.set_ylabel("D1 PSNR, dB (peak 59.70 m, symmetric)")
        ax.set_title(f"{ds}: median over scans; open markers: PCL profiles, lex3d word-only", fontsize=10)
        ax.grid(True, which="both", linewidth=0.3)
        ax.legend(fontsize=8, loc="lower right")
        path = os.path.join(out_dir, f"rd_{ds}.png")
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--targets", type=float, nargs="+", default=[60.0, 70.0, 75.0, 82.2, 86.0])
    args = ap.parse_args()
    rows = load_jsonl(os.path.join(args.out, "rows.jsonl"))
    if not rows:
        sys.exit(f"rd_report.py: no rows in {args.out}/rows.jsonl")
    alphabets = load_jsonl(os.path.join(args.out, "alphabets.jsonl"))
    summary = summarise(rows)
    text, interp = tables(summary, alphabets, args.targets, rows)
    with open(os.path.join(args.out, "rows.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    with open(os.path.join(args.out, "rd.json"), "w") as f:
        json.dump({"rows": rows, "medians": summary, "interpolated_bpp": interp, "alphabets": alphabets,
                   "targets_db": args.targets}, f, indent=1)
    with open(os.path.join(args.out, "report.md"), "w") as f:
        f.write(text + "\n")
    print(text)
    for p in plot(summary, args.targets, args.out):
        print(f"plot: {p}")
    errors = [r for r in rows if "error" in r]
    if errors:
        print(f"{len(errors)} failed runs (see rows.csv, column error)")


if __name__ == "__main__":
    main()
