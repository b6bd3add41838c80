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
  lex3d-mse    lex3d compress --objective mse (the fewest bits for the mean squared error
               within the bound), the residual layer alone, over LEX3D_MSE_E; where
               `lex3d compress --help` lists --objective
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
import math
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
# (--objective mse reaches a PSNR at about 9/5 of the default's bound)
LEX3D_MSE_E = LEX3D_E + [0.3, 0.4]
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


# Sets read from DATA by globs, one line each: name, glob (or tuple of globs), lex3d --format
# (or None), spinning lidar (G-PCC predictive + angular runs on it), and where G-PCC's laser
# table comes from: None (estimated from the points, bench/laser_table.py), "ouster" (the
# metadata JSON beside the capture) or a published sensor table (LASER_TABLES). A set whose
# first file lex3d cannot read (lex3d_convert fails) is skipped with a note.
# Raw logs (.pcap) hold one scan a complete turn: `lex3d convert` writes each turn as an
# organised PCD, whose points (lex3d_convert, no-returns dropped) are the reference and the
# baseline codecs' input; lex3d compresses the capture itself (its sensor geometry from the
# log / metadata) and is measured on the same turn.
GLOB_SETS = [
    ("hdl32e", "velodyne/hdl32e_*.pcd", None, True, None),
    ("hdl32e_pcap", "velodyne/hdl32e_*.pcap", None, True, "hdl32e"),
    ("ouster", "ouster/*.pcap", None, True, "ouster"),
    ("vlp16", "velodyne/vlp16_*.pcap", None, True, "vlp16"),
    ("las", ("las/hexbin-crop.las", "las/autzen_trim.las"), None, False, None),
]
SPINNING = {"balm", "kitti00", "newer_college"} | {g[0] for g in GLOB_SETS if g[3]}
OPTIONAL = {g[0] for g in GLOB_SETS}
TABLE_SOURCE = {g[0]: g[4] for g in GLOB_SETS}
DEFAULT_SETS = ["balm", "kitti00", "newer_college", "indoor", "balm_map"] + [g[0] for g in GLOB_SETS]
# Published nominal laser tables (elevation degrees, vertical offset mm): VLP-16 (Velodyne's
# manual: -15 ... +15 degrees in 2 degree steps, interleaved), HDL-32E (bench/laser_table.py's:
# -30.67 ... +10.67 degrees in 4/3 degree steps). No vertical offsets: lex3d's Velodyne reader
# puts every beam's origin at the sensor origin (the VLP-16 manual's per-laser vertical
# corrections of up to 11.2 mm would leave that much fit residual on its points).
LASER_TABLES = {
    "vlp16": ([-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15], [0.0] * 16),
    "hdl32e": ([-30.67 + i * 4.0 / 3.0 for i in range(32)], [0.0] * 32),
}


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
    for name, pattern, fmt, _, _ in GLOB_SETS:
        files = []
        for p in ([pattern] if isinstance(pattern, str) else pattern):
            files += sorted(glob.glob(os.path.join(data, p)))
        out[name] = ([(s, fmt, None) for s in files], None)
    return out


def resampled_sets(root):
    """Sets made by bench/resample_sets.sh: ROOT/<sensor>/*.bin, re-sampled from real scans with
    the sensor's vendor laser table (ROOT/<sensor>/table.json, which G-PCC's angular coding is
    given as the exact table). name -> (scans, None); registered as spinning, optional sets."""
    out = {}
    if not root:
        return out
    for d in sorted(glob.glob(os.path.join(root, "*", "table.json"))):
        sensor = os.path.basename(os.path.dirname(d))
        name = "rs_" + sensor
        files = sorted(glob.glob(os.path.join(os.path.dirname(d), "*.bin")))
        out[name] = ([(s, None, None) for s in files], None)
        SPINNING.add(name)
        OPTIONAL.add(name)
        TABLE_SOURCE[name] = "file:" + d
    return out


def ouster_metadata(pcap):
    """The metadata JSON beside an Ouster capture, found as lex3d finds it: <stem>.json, else the
    stem cut at its last '_', repeatedly."""
    stem = os.path.splitext(pcap)[0]
    while True:
        if os.path.isfile(stem + ".json"):
            return stem + ".json"
        d, b = os.path.split(stem)
        if "_" not in b:
            return None
        stem = os.path.join(d, b.rsplit("_", 1)[0])


def given_table(xyz, tan_t, z0_m, phi, source):
    """A laser table given by metadata or a published table, in laser_table.fit's layout; the fit
    residual (z minus the nearest cone at the point's range) is measured on the points, and
    phi_per_turn (None: from the points, as laser_table.fit) is the given firings a turn."""
    import numpy as np
    import laser_table
    order = np.argsort(tan_t)
    tan_t, z0 = np.asarray(tan_t, dtype=np.float64)[order], np.asarray(z0_m, dtype=np.float64)[order]
    if phi is None:
        phi = laser_table.fit(xyz)["phi_per_turn"]
        phi = [int(np.median(phi))] * len(tan_t)
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    ok = r > 1e-3
    r, z = r[ok], xyz[ok, 2]
    lab = laser_table.assign(r, z, tan_t, z0)
    res = z - (tan_t[lab] * r + z0[lab])
    counts = np.bincount(lab, minlength=len(tan_t))
    return {
        "lasers": int(len(tan_t)), "tan_theta": [float(v) for v in tan_t], "z0_m": [float(v) for v in z0],
        "phi_per_turn": [int(v) for v in phi], "source": source,
        "theta_deg_min": float(np.degrees(np.arctan(tan_t.min()))),
        "theta_deg_max": float(np.degrees(np.arctan(tan_t.max()))),
        "fit_rms_mm": float(1000 * np.sqrt(np.mean(res ** 2))),
        "fit_p95_mm": float(1000 * np.quantile(np.abs(res), 0.95)),
        "points": int(len(r)), "empty_lasers": int((counts == 0).sum()),
    }


def ouster_table(xyz, meta_path):
    """The exact laser table of an Ouster sensor from its metadata: beam i is the cone
    z = tan(alt_i) (r_xy - n) + z_beam, r_xy = horizontal range in the sensor frame, n the lidar
    origin to beam origin distance, z_beam the beam origin's height in the sensor frame
    (lidar_to_sensor_transform, plus beam_to_lidar_transform's height where the metadata has
    one); one firing a column, columns_per_frame a turn."""
    import numpy as np
    with open(meta_path) as f:
        m = json.load(f)
    bi = m.get("beam_intrinsics", m)
    alt = np.radians(np.asarray(bi["beam_altitude_angles"], dtype=np.float64))
    n_mm = float(bi.get("lidar_origin_to_beam_origin_mm", 0.0))
    beam_z_mm = 0.0
    if "beam_to_lidar_transform" in bi:
        t = bi["beam_to_lidar_transform"]
        n_mm, beam_z_mm = float(t[3]), float(t[11])
    l2s = m.get("lidar_intrinsics", m)["lidar_to_sensor_transform"]
    z_mm = float(l2s[11]) + float(l2s[10]) * beam_z_mm
    fmt = m.get("lidar_data_format", m.get("data_format", {}))
    cols = int(fmt.get("columns_per_frame", 0)) or int(str(m.get("lidar_mode", "1024x10")).split("x")[0])
    tan_t = np.tan(alt)
    return given_table(xyz, tan_t, (z_mm - n_mm * tan_t) / 1000.0, [cols] * len(alt),
                       f"metadata:{os.path.basename(meta_path)}")


def numbered(path, index, count):
    """lex3d's name for output `index` of `count` (one file a turn of a raw log): stem_000.ext."""
    if count <= 1:
        return path
    stem, ext = os.path.splitext(path)
    return f"{stem}_{index:03d}{ext}"


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
        # geometry against geometry: the other codecs here code positions only
        self.geometry_only = ["--drop-attributes"] if "--drop-attributes" in help_text else []
        self.has_objective = "--objective" in help_text and self.has_max_error
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
        for k in ("max_error_m", "words_used", "instances", "lex3d_points", "layer_coding", "lex3d_laser_table",
                  "lex3d_laser_fit_rms_m"):
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

    def laser_table(self, ref, scan, source):
        import laser_table
        xyz = laser_table.read_ply_xyz(ref)
        if source == "ouster":
            meta = ouster_metadata(scan)
            if meta is None:
                raise ValueError(f"{scan}: no metadata JSON beside it")
            return ouster_table(xyz, meta)
        if source and source.startswith("file:"):
            with open(source[5:]) as f:
                spec = json.load(f)
            lasers = spec["lasers"]
            tan_t = [math.tan(math.radians(l["elevation_deg"])) for l in lasers]
            return given_table(xyz, tan_t, [l.get("z_offset", 0.0) for l in lasers], [int(spec["columns"])] * len(lasers),
                               "published:" + spec["sensor"])
        if source in LASER_TABLES:
            deg, z_mm = LASER_TABLES[source]
            tan_t = [math.tan(math.radians(d)) for d in deg]
            return given_table(xyz, tan_t, [v / 1000.0 for v in z_mm], None, f"published:{source}")
        return laser_table.fit(xyz)

    def gpcc(self, base, ref, w, spinning, scan=None, table_source=None):
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
        # tmc3 turns a float input into its integer unit by truncating toward zero (measured: on
        # a 1 mm unit the error per axis is -0.5 mm on average for x > 0 and +0.5 mm for x < 0,
        # RMSE 1 mm instead of 0.5 mm). Its input is the reference moved half a unit away from
        # zero on every axis, so that the truncation rounds to the nearest unit; the decoded
        # cloud is still measured against the reference itself.
        xyz_ref = laser_table.read_ply_xyz(ref)
        shifted = {}

        def tmc3_input(unit_m):
            if unit_m not in shifted:
                path = os.path.join(w, f"g_in_{len(shifted)}.ply")
                write_ply_xyz(path, xyz_ref + np.sign(xyz_ref) * (unit_m / 2.0))
                shifted[unit_m] = path
            return shifted[unit_m]

        dec_cmd = [self.tmc3, "--mode=1", f"--compressedStreamPath={stream}", f"--reconstructedDataPath={raw}",
                   "--outputBinaryPly=1", "--outputUnitLength=1"]
        for step in env_list("RD_GPCC_OCTREE_MM", GPCC_OCTREE_STEP_MM, float):
            enc = [self.tmc3, "--mode=0", f"--uncompressedDataPath={tmc3_input(0.001)}",
                   f"--compressedStreamPath={stream}", "--inputScale=1000", f"--positionQuantizationScale={1.0 / step:.10g}", "--trisoupNodeSizeLog2=0",
                   "--mergeDuplicatedPoints=1"] + common
            self.case(base, "gpcc-octree", f"step={step:g}mm", step, enc, dec_cmd, stream, decoded, ref, parse, parse,
                      post=post)
        if not spinning:
            return
        t = self.laser_table(ref, scan, table_source)
        print(f"  laser table ({t['source']}): {t['lasers']} lasers, {t['theta_deg_min']:.2f} to "
              f"{t['theta_deg_max']:.2f} deg, fit residual RMS {t['fit_rms_mm']:.2f} mm, 95 % "
              f"{t['fit_p95_mm']:.2f} mm, azimuth steps per turn {min(t['phi_per_turn'])}-{max(t['phi_per_turn'])}",
              flush=True)
        table = {"lasers": t["lasers"], "laser_fit_rms_mm": t["fit_rms_mm"], "laser_fit_p95_mm": t["fit_p95_mm"],
                 "laser_table_source": t["source"].split(":")[0]}

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
            enc = [self.tmc3, "--mode=0", f"--uncompressedDataPath={tmc3_input(unit)}",
                   f"--compressedStreamPath={stream}"] + pred_args(unit, r, a, residual)
            self.case(base, "gpcc-pred", setting, order, enc, dec_cmd, stream, decoded, ref, parse, parse,
                      post=post, extra=table)

    def lex3d_codec(self, base, scan, fmt, pose_args, ref, w, alphabet, n_scans, turn=0, turns=1):
        def parse_dec(out, err):
            t = last_json(out).get("timings_ms", {})
            return {"ms": t.get("decode", 0.0) + t.get("reconstruct", 0.0)}

        fmt_args = ["--format", fmt] if fmt else []
        # A raw log of several turns gives one model file a turn (l_000.lex3dm, ...): this scan's
        # is measured. A georeferenced input (LAS) decodes to true coordinates in PLY; the
        # float32 .bin holds the local frame the reference PLY is in.
        out_path = os.path.join(w, "l.lex3dm")
        stream = numbered(out_path, turn, turns)
        decoded = os.path.join(w, "l.bin" if scan.lower().endswith(".las") else "l.ply")
        # lex3d: words alone (alphabet learned on the scan, embedded), then the residual layer
        # alone (the default with --max-error). lex3d-seq: the dataset's shared alphabet, words
        # alone and, with a bound, --words auto (words + layer where that file is smaller), its
        # bytes shared by the scans of the run.
        words = [None] if os.environ.get("RD_LEX3D_WORDS", "1") != "0" else []
        own_e = words + (env_list("RD_LEX3D_E", LEX3D_E) if self.has_max_error else [])
        seq_e = words + (env_list("RD_LEX3D_SEQ_E", LEX3D_SEQ_E) if self.has_max_error else [])
        mse_e = env_list("RD_LEX3D_MSE_E", LEX3D_MSE_E) if self.has_objective else []
        for mode, es in (("lex3d", own_e), ("lex3d-seq", seq_e), ("lex3d-mse", mse_e)):
            if mode == "lex3d-seq" and alphabet is None:
                continue
            for e in es:
                e_args = ["--max-error", e] if e is not None else (["--max-error", "none"] if self.has_max_error else [])
                if e is not None and mode == "lex3d-seq":
                    e_args += ["--words", "auto"]
                if mode == "lex3d-mse":
                    e_args += ["--objective", "mse"]
                a_args = ["--alphabet", alphabet["path"]] if mode == "lex3d-seq" else []

                def parse_enc(out, err, e=e):
                    j = last_json(out)
                    f = j["files"][turn]
                    # time_ms covers the whole command: every turn of a raw log, shared out here
                    r = {"ms": j["time_ms"] / turns, "instances": f.get("instances"), "lex3d_points": f.get("points")}
                    if e is not None:
                        res = f.get("residual", {})
                        r["max_error_m"] = e
                        r["words_used"] = res.get("words_used")
                        r["layer_coding"] = res.get("coding")
                        if "laser_table" in res:
                            r["lex3d_laser_table"] = res["laser_table"].get("source")
                            r["lex3d_laser_fit_rms_m"] = res["laser_table"].get("fit_rms_m")
                    return r

                self.case(base, mode, "words" if e is None else f"E={e:g}", 0.0 if e is None else e,
                          [self.lex3d, "compress", scan, "-o", out_path, "--json"] + fmt_args + pose_args + a_args + e_args + self.geometry_only,
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
        # one entry a scan: (file, format, pose line, file the reference is read from, turn, turns)
        entries = []
        for scan, fmt, li in scans:
            if not scan.lower().endswith(".pcap"):
                entries.append((scan, fmt, li, scan, 0, 1))
                continue
            pcd = os.path.join(w, os.path.splitext(os.path.basename(scan))[0] + ".pcd")
            rc, out, err, _, _ = self.runner.run([self.lex3d, "convert", scan, pcd])
            turns = len([l for l in out.split("\n") if " -> " in l])
            if rc != 0 or turns == 0:
                print(f"  FAILED lex3d convert {scan}: {err.strip()[-300:]}", flush=True)
                self.failures += 1
                continue
            print(f"  {os.path.basename(scan)}: {turns} turn(s)", flush=True)
            entries += [(scan, fmt, li, numbered(pcd, k, turns), k, turns) for k in range(turns)]
        alphabet = self.learn(name, scans, poses, w) if (
            os.environ.get("RD_LEX3D_WORDS", "1") != "0" or not self.has_max_error) else None
        pose_lines = open(poses).read().split("\n") if poses else None
        for n, (scan, fmt, li, src, turn, turns) in enumerate(entries, 1):
            t0 = time.perf_counter()
            ref = os.path.join(w, "ref.ply")
            cmd = [self.convert, src, ref] + (["--format", fmt] if fmt and src == scan else [])
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
            label = os.path.basename(scan) + (f"#{turn}" if turns > 1 else "")
            base = {"dataset": name, "scan": label, "points": points}
            self.draco(base, ref, w)
            self.pcl_octree(base, ref, w)
            self.octomap_codec(base, ref, w)
            if self.tmc3:
                self.gpcc(base, ref, w, name in SPINNING, scan, TABLE_SOURCE.get(name))
            self.lex3d_codec(base, scan, fmt, pose_args, ref, w, alphabet, len(entries), turn, turns)
            el = time.perf_counter() - t_start
            print(f"  [{name} {n}/{len(entries)}] {label}: {points} points, "
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
    ap.add_argument("--resampled", help="sets made by bench/resample_sets.sh (datasets rs_<sensor>)")
    ap.add_argument("datasets", nargs="*", default=DEFAULT_SETS)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    all_sets = datasets(args.data, args.all_scans)
    all_sets.update(resampled_sets(args.resampled))
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
