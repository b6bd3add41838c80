#!/usr/bin/python3
"""Rate-distortion runs of bench/rd.sh: lex3d and three baseline codecs on the same scans.

Usage (normally through bench/rd.sh):
  rd.py --build BUILD_DIR --data DATA_DIR --out OUT_DIR [--all-scans] [--keep] [dataset...]

For every dataset, every scan is first converted to a PLY of its x y z points
(lex3d_convert: the same reader as lex3d, non-finite points and no-return readings
dropped). That PLY is the reference every decoded cloud is measured against and the
input of the baseline codecs; lex3d reads the original file. Then every (codec, setting)
encodes and decodes the scan, each step in its own process under /usr/bin/time (peak
resident memory), and lex3d_eval_clouds measures the decoded cloud. One JSON object a
run is appended to OUT_DIR/rows.jsonl; bench/rd_report.py turns the rows into tables,
CSV/JSON and plots.

Codecs and settings:
  draco-kd     draco_encoder -point_cloud -cl 10 (kd-tree), -qp over DRACO_KD_QP
  draco-seq    draco_encoder -point_cloud -cl 0 (sequential), -qp over DRACO_SEQ_QP
  pcl-octree   pcl::io::OctreePointCloudCompression: PCL's six colourless profiles, and
               MANUAL_CONFIGURATION with point resolution = octree resolution over PCL_RES
  octomap      OcTree of the points (each point's voxel marked occupied, no ray casting),
               .bt file; decoded = centres of the occupied finest voxels; over OCTOMAP_RES
  lex3d        lex3d compress SCAN (alphabet learned on the scan and embedded)
  lex3d-seq    one alphabet learned per dataset (lex3d learn on up to 4 of its scans),
               each scan compressed with --alphabet; the alphabet file's bytes are shared
               out equally over the dataset's scans in this run
  Both lex3d modes are word-only unless `lex3d compress --help` lists --max-error; then
  lex3d sweeps LEX3D_E with the residual layer alone (lex3d's default with --max-error) and
  lex3d-seq sweeps LEX3D_SEQ_E with --words auto (per scan, words + layer or the layer alone,
  whichever file is smaller); both also run word-only.

Times: encode_ms / decode_ms are what each codec reports about itself (Draco's "ms to
encode/decode", the bench tools' timers around PCL's / OctoMap's calls, lex3d compress's
time_ms (whole command: reading, learning when it learns, modelling, writing) and
decompress's decode + reconstruct); *_wall_ms are the process wall times.
"""

import argparse
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

DRACO_KD_QP = [8, 9, 10, 11, 12, 13, 14, 15, 16, 18]
DRACO_SEQ_QP = [10, 12, 13, 14, 16]
PCL_PROFILES = ["LOW_RES_ONLINE", "MED_RES_ONLINE", "HIGH_RES_ONLINE",
                "LOW_RES_OFFLINE", "MED_RES_OFFLINE", "HIGH_RES_OFFLINE"]
PCL_RES = [0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2]
OCTOMAP_RES = [0.005, 0.01, 0.02, 0.05, 0.1, 0.2]
LEX3D_E = [0.005, 0.008, 0.012, 0.02, 0.035, 0.06, 0.1, 0.15, 0.2]
LEX3D_SEQ_E = LEX3D_E
LEARN_SCANS = 4
# G-PCC (TMC13's tmc3, when --tmc3 is given). Octree: integer millimetres in, then
# positionQuantizationScale = 1 / step for these steps (mm). Predictive + angular: CTC's six
# lossy (radius inv scale log2, azimuth scale log2) pairs with no cartesian residual, on
# integer millimetres; and the cartesian residual coded losslessly on integers of these units (mm).
GPCC_OCTREE_STEP_MM = [1, 2, 4, 8, 16, 32, 64, 128, 256]
GPCC_PRED_RA = [(1, 12), (2, 11), (4, 9), (5, 8), (7, 7), (8, 7)]
GPCC_PRED_RES_MM = [2, 5, 10, 20, 50, 100]
MAP_SCANS = 10   # balm_map: scans merged into one map,
MAP_STEP = 3     # this many scans apart (3 s),
MAP_COUNT = 3    # maps, spread over the walk


# Sets read from DATA by a glob, one line each: name, glob, lex3d --format (or None), spinning
# lidar (G-PCC predictive + angular runs on it). A set whose first file lex3d cannot read
# (lex3d_convert fails) is skipped with a note, so sets for inputs lex3d does not read yet can
# stand here.
GLOB_SETS = [
    ("hdl32e", "velodyne/hdl32e_*.pcd", None, True),
    ("ouster", "ouster/*.pcap", None, True),
    ("vlp16", "velodyne/vlp16_*.pcap", None, True),
    ("las", "las/*.las", None, False),
]
SPINNING = {"balm", "kitti00", "newer_college"} | {n for n, _, _, sp in GLOB_SETS if sp}
OPTIONAL = {n for n, _, _, _ in GLOB_SETS}
DEFAULT_SETS = ["balm", "kitti00", "newer_college", "indoor", "balm_map"] + [n for n, _, _, _ in GLOB_SETS]


def env_list(name, default, kind=float):
    text = os.environ.get(name)
    if text is None:
        return default
    return [kind(t) for t in text.split()]


def datasets(data, all_scans):
    """name -> (list of (scan path, format or None, pose line index or None), poses file or None)."""
    out = {}
    balm = sorted(glob.glob(os.path.join(data, "balm", "[0-9]*.bin")))
    idx = list(range(len(balm))) if all_scans else list(range(0, len(balm), 10))
    out["balm"] = ([(balm[i], None, i) for i in idx], os.path.join(data, "balm", "poses.txt"))
    kitti = sorted(glob.glob(os.path.join(data, "kitti00", "[0-9]*.bin")))
    out["kitti00"] = ([(s, None, None) for s in kitti], None)
    nc = sorted(glob.glob(os.path.join(data, "newer_college", "raw_0*.bin")))
    out["newer_college"] = ([(s, "binxyz", None) for s in nc], None)
    indoor = sorted(glob.glob(os.path.join(data, "indoor", "room_scan*.pcd")))
    indoor += sorted(glob.glob(os.path.join(data, "indoor", "scan*.3d")))
    out["indoor"] = ([(s, None, None) for s in indoor], None)
    # Maps: MAP_SCANS balm scans MAP_STEP apart, merged in the world frame by their poses
    # (made by merge_balm when the dataset runs): clouds with no one viewpoint.
    poses = os.path.join(data, "balm", "poses.txt")
    span = MAP_STEP * (MAP_SCANS - 1) + 1
    if os.path.exists(poses) and len(balm) >= span:
        starts = range(0, len(balm) - span + 1, max(1, (len(balm) - span) // (MAP_COUNT - 1)))
        out["balm_map"] = ([(("map", [s + MAP_STEP * k for k in range(MAP_SCANS)]), None, None)
                            for s in list(starts)[:MAP_COUNT]], None)
    for name, pattern, fmt, _ in GLOB_SETS:
        out[name] = ([(s, fmt, None) for s in sorted(glob.glob(os.path.join(data, pattern)))], None)
    return out


def spread(items, n):
    """n evenly spaced items of the list (all when n is None or not smaller)."""
    if not n or n >= len(items):
        return items
    return [items[round(i * (len(items) - 1) / max(n - 1, 1))] for i in range(n)]


def write_ply_xyz(path, xyz):
    import numpy as np
    m = np.ascontiguousarray(xyz, dtype="<f4")
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(m)}\n"
                 "property float x\nproperty float y\nproperty float z\nend_header\n").encode())
        f.write(m.tobytes())


def merge_balm(data, lines, path):
    """Writes the balm scans of pose lines `lines` (frames.txt order), moved into the world
    frame by their poses, as one binary PLY of x y z."""
    import numpy as np
    frames = [f.strip() for f in open(os.path.join(data, "balm", "frames.txt")) if f.strip()]
    poses = np.loadtxt(os.path.join(data, "balm", "poses.txt")).reshape(-1, 3, 4)
    parts = []
    for i in lines:
        xyz = np.fromfile(os.path.join(data, "balm", frames[i]), dtype="<f4").reshape(-1, 4)[:, :3].astype(np.float64)
        xyz = xyz[np.isfinite(xyz).all(axis=1)]
        parts.append(xyz @ poses[i][:, :3].T + poses[i][:, 3])
    m = np.vstack(parts).astype("<f4")
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(m)}\n"
                 "property float x\nproperty float y\nproperty float z\nend_header\n").encode())
        f.write(m.tobytes())


class Runner:
    def __init__(self, tmp):
        self.tmp = tmp
        self.timefile = os.path.join(tmp, "time.txt")

    def run(self, cmd):
        """Runs cmd under /usr/bin/time; returns (rc, stdout, stderr, wall_ms, peak_kb)."""
        t0 = time.perf_counter()
        p = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", self.timefile] + [str(c) for c in cmd],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="replace")
        wall = 1000.0 * (time.perf_counter() - t0)
        peak = None
        try:
            with open(self.timefile) as f:
                lines = [l for l in f.read().split("\n") if l.strip()]
            peak = int(lines[-1])
        except (OSError, ValueError, IndexError):
            pass
        return p.returncode, p.stdout, p.stderr, wall, peak


def last_json(text):
    for line in reversed(text.strip().split("\n")):
        line = line.strip()
        if line.startswith("{"):
            return json.loads(line)
    raise ValueError("no JSON line in output")


class Bench:
    def __init__(self, args):
        self.args = args
        self.data = args.data
        b = args.build
        self.lex3d = args.lex3d or os.path.join(b, "lex3d")
        self.eval = os.path.join(b, "bench", "lex3d_eval_clouds")
        self.convert = os.path.join(b, "bench", "lex3d_convert")
        self.pcl = os.path.join(b, "bench", "lex3d_bench_pcl_octree")
        self.octomap = os.path.join(b, "bench", "lex3d_bench_octomap")
        self.tmc3 = args.tmc3
        self.tmp = tempfile.mkdtemp(prefix="rd_", dir=args.out)
        self.runner = Runner(self.tmp)
        self.rows_path = os.path.join(args.out, "rows.jsonl")
        help_text = subprocess.run([self.lex3d, "compress", "--help"], stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True).stdout
        self.has_max_error = "--max-error" in help_text
        self.failures = 0

    def close(self):
        if not self.args.keep:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def emit(self, row):
        with open(self.rows_path, "a") as f:
            f.write(json.dumps(row) + "\n")

    def measure(self, ref, decoded):
        rc, out, err, _, _ = self.runner.run([self.eval, ref, decoded, "--threads", "2"])
        if rc != 0:
            raise RuntimeError("lex3d_eval_clouds: " + err.strip())
        return last_json(out)

    def case(self, base, codec, setting, order, enc_cmd, dec_cmd, stream, decoded, ref, parse_enc, parse_dec,
             extra_bytes=0.0, post=None, extra=None):
        """One (codec, setting, scan): encode, decode, measure, emit a row. Returns the row or None."""
        row = dict(base, codec=codec, setting=setting, order=order)
        try:
            rc, out, err, wall_e, peak_e = self.runner.run(enc_cmd)
            if rc != 0:
                raise RuntimeError(f"encode exit {rc}: {err.strip()[-300:]}")
            enc = parse_enc(out, err)
            rc, out, err, wall_d, peak_d = self.runner.run(dec_cmd)
            if rc != 0:
                raise RuntimeError(f"decode exit {rc}: {err.strip()[-300:]}")
            dec = parse_dec(out, err)
            if post is not None:
                post()  # untimed: the decoded cloud into the PLY lex3d_eval_clouds compares
            stream_bytes = os.path.getsize(stream)
            m = self.measure(ref, decoded)
        except (RuntimeError, ValueError, OSError) as e:
            self.failures += 1
            row["error"] = str(e)
            print(f"  FAILED {codec} {setting} on {base['scan']}: {e}", flush=True)
            self.emit(row)
            return None
        total = stream_bytes + extra_bytes
        row.update(
            bytes=total, stream_bytes=stream_bytes, shared_bytes=extra_bytes,
            bpp=8.0 * total / base["points"],
            encode_ms=enc.get("ms"), decode_ms=dec.get("ms"),
            encode_wall_ms=wall_e, decode_wall_ms=wall_d,
            encode_peak_kb=peak_e, decode_peak_kb=peak_d,
            n_decoded=m["n_decoded"], d1_psnr_db=m["d1_psnr_db"], rmse_m=m["rmse_m"],
            hausdorff_m=m["hausdorff_m"], chamfer_m=m["chamfer_m"], mse_ab=m["mse_ab"], mse_ba=m["mse_ba"],
            coverage_2cm=m["coverage_2cm"], coverage_5cm=m["coverage_5cm"],
            outliers_2cm=m["outliers_2cm"], outliers_5cm=m["outliers_5cm"])
        row.update(extra or {})
        for k in ("max_error_m", "words_used", "instances"):
            if k in enc:
                row[k] = enc[k]
        if "max_error_m" in row and row["hausdorff_m"] > row["max_error_m"] * 1.0001 + 1e-6:
            print(f"  NOTE {codec} {setting} on {base['scan']}: Hausdorff {row['hausdorff_m']:.4f} m "
                  f"> max error {row['max_error_m']} m", flush=True)
        self.emit(row)
        return row

    # --- codecs -------------------------------------------------------------------------
    def draco(self, base, ref, w):
        def parse_enc(out, err):
            m = re.search(r"\((\d+) ms to encode\)", out + err)
            return {"ms": float(m.group(1))} if m else {}

        def parse_dec(out, err):
            m = re.search(r"\((\d+) ms to decode\)", out + err)
            return {"ms": float(m.group(1))} if m else {}

        stream, decoded = os.path.join(w, "d.drc"), os.path.join(w, "d.ply")
        for name, cl, qps in (("draco-kd", 10, env_list("RD_DRACO_KD_QP", DRACO_KD_QP, int)),
                              ("draco-seq", 0, env_list("RD_DRACO_SEQ_QP", DRACO_SEQ_QP, int))):
            for qp in qps:
                self.case(base, name, f"qp{qp}", qp,
                          ["draco_encoder", "-point_cloud", "-i", ref, "-o", stream, "-qp", qp, "-cl", cl],
                          ["draco_decoder", "-i", stream, "-o", decoded], stream, decoded, ref, parse_enc, parse_dec)

    def pcl_octree(self, base, ref, w):
        def parse_enc(out, err):
            return {"ms": last_json(out)["encode_ms"]}

        def parse_dec(out, err):
            return {"ms": last_json(out)["decode_ms"]}

        stream, decoded = os.path.join(w, "p.pclo"), os.path.join(w, "p.ply")
        for i, prof in enumerate(PCL_PROFILES):
            self.case(base, "pcl-octree", prof, -100 + i, [self.pcl, "encode", ref, stream, "--profile", prof],
                      [self.pcl, "decode", stream, decoded], stream, decoded, ref, parse_enc, parse_dec)
        for r in env_list("RD_PCL_RES", PCL_RES):
            self.case(base, "pcl-octree", f"r={r:g}", r, [self.pcl, "encode", ref, stream, "--resolution", r],
                      [self.pcl, "decode", stream, decoded], stream, decoded, ref, parse_enc, parse_dec)

    def octomap_codec(self, base, ref, w):
        def parse_enc(out, err):
            j = last_json(out)
            if j.get("dropped"):
                print(f"  NOTE octomap dropped {j['dropped']} points outside the key range", flush=True)
            return {"ms": j["encode_ms"]}

        def parse_dec(out, err):
            return {"ms": last_json(out)["decode_ms"]}

        stream, decoded = os.path.join(w, "o.bt"), os.path.join(w, "o.ply")
        for r in env_list("RD_OCTOMAP_RES", OCTOMAP_RES):
            self.case(base, "octomap", f"r={r:g}", r, [self.octomap, "encode", ref, stream, "--resolution", r],
                      [self.octomap, "decode", stream, decoded], stream, decoded, ref, parse_enc, parse_dec)

    def gpcc(self, base, ref, w, spinning):
        """G-PCC (tmc3): octree geometry, lossy by positionQuantizationScale, on integer mm; and,
        on spinning-lidar scans, predictive geometry with angular coding and the scan's laser
        table (bench/laser_table.py). Geometry only (no attribute coded), trisoup off."""
        import numpy as np
        import laser_table

        def parse(out, err):
            # the codec's own figure: geometry coding time (user CPU), without PLY I/O
            m = re.search(r"positions processing time \(user\): ([0-9.]+) s", out)
            return {"ms": 1000.0 * float(m.group(1))} if m else {}

        stream, raw, decoded = os.path.join(w, "g.bin"), os.path.join(w, "g_raw.ply"), os.path.join(w, "g.ply")

        def post():
            write_ply_xyz(decoded, laser_table.read_ply_xyz(raw))

        common = ["--srcUnit=1", "--srcUnitLength=1", "--disableAttributeCoding=1"]
        dec_cmd = [self.tmc3, "--mode=1", f"--compressedStreamPath={stream}", f"--reconstructedDataPath={raw}",
                   "--outputBinaryPly=1", "--outputUnitLength=1"]
        for step in env_list("RD_GPCC_OCTREE_MM", GPCC_OCTREE_STEP_MM, float):
            enc = [self.tmc3, "--mode=0", f"--uncompressedDataPath={ref}", f"--compressedStreamPath={stream}",
                   "--inputScale=1000", f"--positionQuantizationScale={1.0 / step:.10g}", "--trisoupNodeSizeLog2=0",
                   "--mergeDuplicatedPoints=1"] + common
            self.case(base, "gpcc-octree", f"step={step:g}mm", step, enc, dec_cmd, stream, decoded, ref, parse, parse,
                      post=post)
        if not spinning:
            return
        t = laser_table.fit(laser_table.read_ply_xyz(ref))
        print(f"  laser table ({t['source']}): {t['lasers']} lasers, {t['theta_deg_min']:.2f} to "
              f"{t['theta_deg_max']:.2f} deg, fit residual RMS {t['fit_rms_mm']:.2f} mm, 95 % "
              f"{t['fit_p95_mm']:.2f} mm, azimuth steps per turn {min(t['phi_per_turn'])}-{max(t['phi_per_turn'])}",
              flush=True)
        table = {"lasers": t["lasers"], "laser_fit_rms_mm": t["fit_rms_mm"], "laser_fit_p95_mm": t["fit_p95_mm"]}

        def pred_args(unit_m, r_log2, a_log2, residual):
            speed = max(1, round(2 ** (a_log2 + 12) / max(t["phi_per_turn"])))
            return [f"--inputScale={1.0 / unit_m:.10g}", "--geomTreeType=1", "--angularEnabled=1",
                    "--sortInputByAzimuth=1", "--predGeomSort=0", "--predGeomAzimuthSortPrecision=1024",
                    f"--numLasers={t['lasers']}",
                    "--lasersTheta=" + ",".join(f"{v:.9f}" for v in t["tan_theta"]),
                    "--lasersZ=" + ",".join(f"{-v / unit_m:.4f}" for v in t["z0_m"]),
                    "--lasersNumPhiPerTurn=" + ",".join(str(v) for v in t["phi_per_turn"]),
                    f"--positionRadiusInvScaleLog2={r_log2}", f"--positionAzimuthScaleLog2={a_log2}",
                    f"--positionAzimuthSpeed={speed}", "--resRContextQphiThresholdPresentFlag=1",
                    f"--resRContextQphiThreshold={int(1600 / speed)}",
                    f"--secondaryResidualDisabled={0 if residual else 1}"] + common

        # order: the quantisation step in mm (radius step, or the integer unit), for the plot
        ra = env_list("RD_GPCC_PRED_RA", [f"{r}:{a}" for r, a in GPCC_PRED_RA], str)
        runs = [(f"R{r}A{a}", 0.001, int(r), int(a), False, 2.0 ** int(r)) for r, a in (x.split(":") for x in ra)]
        runs += [(f"res={u:g}mm", u / 1000.0, 0, 12, True, u)
                 for u in env_list("RD_GPCC_PRED_RES_MM", GPCC_PRED_RES_MM, float)]
        for setting, unit, r, a, residual, order in runs:
            enc = [self.tmc3, "--mode=0", f"--uncompressedDataPath={ref}", f"--compressedStreamPath={stream}"] + \
                pred_args(unit, r, a, residual)
            self.case(base, "gpcc-pred", setting, order, enc, dec_cmd, stream, decoded, ref, parse, parse,
                      post=post, extra=table)

    def lex3d_codec(self, base, scan, fmt, pose_args, ref, w, alphabet, n_scans):
        def parse_dec(out, err):
            t = last_json(out).get("timings_ms", {})
            return {"ms": t.get("decode", 0.0) + t.get("reconstruct", 0.0)}

        fmt_args = ["--format", fmt] if fmt else []
        stream, decoded = os.path.join(w, "l.lex3dm"), os.path.join(w, "l.ply")
        # lex3d: words alone (alphabet learned on the scan, embedded), then the residual layer
        # alone (the default with --max-error). lex3d-seq: the dataset's shared alphabet, words
        # alone and, with a bound, --words auto (words + layer where that file is smaller), its
        # bytes shared by the scans of the run.
        own_e = [None] + (env_list("RD_LEX3D_E", LEX3D_E) if self.has_max_error else [])
        seq_e = [None] + (env_list("RD_LEX3D_SEQ_E", LEX3D_SEQ_E) if self.has_max_error else [])
        for mode, es in (("lex3d", own_e), ("lex3d-seq", seq_e)):
            if mode == "lex3d-seq" and alphabet is None:
                continue
            for e in es:
                e_args = ["--max-error", e] if e is not None else []
                if e is not None and mode == "lex3d-seq":
                    e_args += ["--words", "auto"]
                a_args = ["--alphabet", alphabet["path"]] if mode == "lex3d-seq" else []

                def parse_enc(out, err, e=e):
                    j = last_json(out)
                    r = {"ms": j["time_ms"], "instances": j["files"][0].get("instances")}
                    if e is not None:
                        r["max_error_m"] = e
                        r["words_used"] = j["files"][0].get("residual", {}).get("words_used")
                    return r

                self.case(base, mode, "words" if e is None else f"E={e:g}", 0.0 if e is None else e,
                          [self.lex3d, "compress", scan, "-o", stream, "--json"] + fmt_args + pose_args + a_args + e_args,
                          [self.lex3d, "decompress", stream, "-o", decoded, "--json"] + a_args,
                          stream, decoded, ref, parse_enc, parse_dec,
                          extra_bytes=(alphabet["bytes"] / n_scans) if mode == "lex3d-seq" else 0.0)

    # --- datasets -----------------------------------------------------------------------
    def learn(self, name, scans, poses, w):
        """One alphabet for the dataset, learned on up to LEARN_SCANS evenly spaced scans."""
        k = min(LEARN_SCANS, len(scans))
        pick = sorted({round(i * (len(scans) - 1) / max(k - 1, 1)) for i in range(k)})
        chosen = [scans[i] for i in pick]
        cmd = [self.lex3d, "learn"] + [s for s, _, _ in chosen]
        fmts = {f for _, f, _ in chosen if f}
        if fmts:
            cmd += ["--format", fmts.pop()]
        if poses:
            lines = open(poses).read().split("\n")
            p = os.path.join(w, "learn_poses.txt")
            with open(p, "w") as f:
                for _, _, li in chosen:
                    f.write(lines[li] + "\n")
            cmd += ["--poses", p]
        path = os.path.join(self.args.out, f"{name}.lex3da")
        cmd += ["-o", path, "--json"]
        rc, out, err, wall, peak = self.runner.run(cmd)
        if rc != 0:
            print(f"  FAILED lex3d learn for {name}: {err.strip()[-300:]}", flush=True)
            self.failures += 1
            return None
        j = last_json(out)
        info = {"dataset": name, "path": path, "bytes": os.path.getsize(path), "words": j.get("words"),
                "learn_scans": [os.path.basename(s) for s, _, _ in chosen], "learn_wall_ms": wall, "learn_peak_kb": peak}
        with open(os.path.join(self.args.out, "alphabets.jsonl"), "a") as f:
            f.write(json.dumps(info) + "\n")
        print(f"  alphabet: {info['words']} words, {info['bytes']} bytes, learned on {len(chosen)} scans "
              f"in {wall / 1000:.1f} s", flush=True)
        return info

    def dataset(self, name, scans, poses, t_start):
        w = os.path.join(self.tmp, name)
        os.makedirs(w, exist_ok=True)
        print(f"[{name}] {len(scans)} scans", flush=True)
        made = []
        for scan, fmt, li in scans:
            if isinstance(scan, tuple):  # a map to merge first
                lines = scan[1]
                scan = os.path.join(w, f"map_{lines[0]:03d}.ply")
                merge_balm(self.data, lines, scan)
            made.append((scan, fmt, li))
        scans = made
        if name in OPTIONAL:
            probe = os.path.join(w, "probe.ply")
            fmt = scans[0][1]
            rc, out, err, _, _ = self.runner.run([self.convert, scans[0][0], probe] + (["--format", fmt] if fmt else []))
            if rc != 0:
                print(f"[{name}] skipped: lex3d does not read {os.path.basename(scans[0][0])} yet "
                      f"({err.strip().splitlines()[-1] if err.strip() else 'exit ' + str(rc)})", flush=True)
                return
        alphabet = self.learn(name, scans, poses, w)
        pose_lines = open(poses).read().split("\n") if poses else None
        for n, (scan, fmt, li) in enumerate(scans, 1):
            t0 = time.perf_counter()
            ref = os.path.join(w, "ref.ply")
            cmd = [self.convert, scan, ref] + (["--format", fmt] if fmt else [])
            rc, out, err, _, _ = self.runner.run(cmd)
            if rc != 0:
                print(f"  FAILED converting {scan}: {err.strip()}", flush=True)
                self.failures += 1
                continue
            points = last_json(out)["points"]
            pose_args = []
            if pose_lines is not None:
                p = os.path.join(w, "pose.txt")
                with open(p, "w") as f:
                    f.write(pose_lines[li] + "\n")
                pose_args = ["--poses", p]
            base = {"dataset": name, "scan": os.path.basename(scan), "points": points}
            self.draco(base, ref, w)
            self.pcl_octree(base, ref, w)
            self.octomap_codec(base, ref, w)
            if self.tmc3:
                self.gpcc(base, ref, w, name in SPINNING)
            self.lex3d_codec(base, scan, fmt, pose_args, ref, w, alphabet, len(scans))
            el = time.perf_counter() - t_start
            print(f"  [{name} {n}/{len(scans)}] {os.path.basename(scan)}: {points} points, "
                  f"{time.perf_counter() - t0:.0f} s (elapsed {int(el // 60)}:{int(el % 60):02d})", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--all-scans", action="store_true", help="every balm scan (default: every 10th)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary directory")
    ap.add_argument("--lex3d", help="the lex3d binary (default BUILD/lex3d)")
    ap.add_argument("--tmc3", help="MPEG G-PCC's tmc3 binary (TMC13); G-PCC is skipped without it")
    ap.add_argument("--scans", type=int, help="at most this many scans a dataset, evenly spaced")
    ap.add_argument("datasets", nargs="*", default=DEFAULT_SETS)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    all_sets = datasets(args.data, args.all_scans)
    for d in args.datasets:
        if d not in all_sets:
            sys.exit(f"rd.py: unknown dataset {d} (known: {', '.join(all_sets)})")
        if not all_sets[d][0] and d not in OPTIONAL:
            sys.exit(f"rd.py: no scans for {d} under {args.data}")
    bench = Bench(args)
    print(f"lex3d compress --max-error: {'yes, residual sweep' if bench.has_max_error else 'absent, word-only'}",
          flush=True)
    print(f"G-PCC: {bench.tmc3 if bench.tmc3 else 'skipped (no tmc3 given)'}", flush=True)
    t_start = time.perf_counter()
    try:
        for d in args.datasets:
            scans, poses = all_sets[d]
            if not scans:
                print(f"[{d}] skipped: no input files under {args.data}", flush=True)
                continue
            bench.dataset(d, spread(scans, args.scans), poses, t_start)
    finally:
        bench.close()
    el = time.perf_counter() - t_start
    print(f"rd.py: done in {int(el // 60)}:{int(el % 60):02d}, {bench.failures} failed runs", flush=True)


if __name__ == "__main__":
    main()
