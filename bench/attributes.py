#!/usr/bin/env python3
"""Cost of the intensity attribute, bits a point, lex3d against Draco and G-PCC.

For each scan: lex3d's ATTR chunk (formats/model.md §2.10) as `compress --json` reports it,
with a residual layer of --max-error (words off), thinned (the default) and with
--keep-all-points (one decoded point an input point); Draco (draco_encoder, -point_cloud)
with the intensity as the red channel of a colour (uint8: Draco keeps it exactly), the
cost being the size with the colour less the size without; G-PCC (tmc3) with the intensity
as `reflectance` (predicting transform, qp 4: step 1, lossless), the cost being the
attribute bytes tmc3 reports. The intensities go to Draco and G-PCC as the integers lex3d
finds (value / step, the step derived from the data as lex3d does), so all three code the
same values. Draco and G-PCC get integer-millimetre positions.
"""
import argparse
import json
import os
import re
import struct
import subprocess
import sys
import tempfile

import numpy as np


def read_ply(path):
    """The binary PLY lex3d convert writes: x y z (float or double), intensity float, ..."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    n = 0
    props = []
    for line in header:
        t = line.split()
        if t[:2] == ["element", "vertex"]:
            n = int(t[2])
        elif t and t[0] == "property":
            props.append((t[2], {"float": "<f4", "double": "<f8", "uchar": "u1", "ushort": "<u2"}[t[1]]))
    arr = np.frombuffer(data, dtype=np.dtype(props), count=n, offset=end)
    xyz = np.stack([arr["x"], arr["y"], arr["z"]], 1).astype(np.float64)
    inten = arr["intensity"].astype(np.float32) if "intensity" in arr.dtype.names else None
    return xyz, inten


def integer_step(values):
    """The largest step (powers of ten, then of two) that maps every value to an integer exactly."""
    steps = sorted([10.0 ** -e for e in range(0, 10)] + [2.0 ** -e for e in range(1, 25)], reverse=True)
    for s in steps:
        k = np.round(values.astype(np.float64) / s)
        if np.all((k * s).astype(np.float32) == values):
            return s, k.astype(np.int64)
    return None, None


def write_ply(path, xyz_mm, props):
    """Binary PLY: float x y z (integer millimetres), then each (name, ply type, array)."""
    types = {"uchar": "u1", "ushort": "<u2"}
    dt = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")] + [(n, types[t]) for n, t, _ in props]
    arr = np.zeros(len(xyz_mm), dtype=dt)
    for a, name in enumerate("xyz"):
        arr[name] = xyz_mm[:, a]
    for n, _, v in props:
        arr[n] = v
    head = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(arr)
    head += "property float x\nproperty float y\nproperty float z\n"
    head += "".join("property %s %s\n" % (t, n) for n, t, _ in props)
    head += "end_header\n"
    with open(path, "wb") as f:
        f.write(head.encode("ascii"))
        f.write(arr.tobytes())


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError("%s failed (%d): %s" % (cmd[0], r.returncode, r.stderr.strip()[-400:]))
    return r.stdout


def lex3d_cost(lex3d, scan, w, max_error, keep_all, extra):
    out = os.path.join(w, "m.lex3dm")
    cmd = [lex3d, "compress", scan, "-o", out, "--max-error", str(max_error), "--words", "off", "--json"] + extra
    if keep_all:
        cmd.append("--keep-all-points")
    j = json.loads(run(cmd).strip().splitlines()[-1])
    f = j["files"][0]
    by = {a["name"]: a for a in f.get("attributes", [])}
    decoded = f["residual"]["kept_word_points"] + f["residual"]["coded_points"]
    return by, f["points"], decoded, f.get("attributes_dropped", [])


def draco_cost(w, xyz_mm, k):
    if k.max() > 255 or k.min() < 0:
        return None
    base = os.path.join(w, "d0.ply")
    col = os.path.join(w, "d1.ply")
    z = np.zeros(len(k), dtype=np.uint8)
    write_ply(base, xyz_mm, [])
    write_ply(col, xyz_mm, [("red", "uchar", k.astype(np.uint8)), ("green", "uchar", z), ("blue", "uchar", z)])
    sizes = []
    for p in (base, col):
        o = os.path.join(w, "d.drc")
        run(["draco_encoder", "-point_cloud", "-i", p, "-o", o, "-qp", "0", "-cl", "10"])
        sizes.append(os.path.getsize(o))
    return 8.0 * (sizes[1] - sizes[0]) / len(k)


def gpcc_cost(tmc3, w, xyz_mm, k):
    if k.min() < 0 or k.max() > 65535:
        return None
    p = os.path.join(w, "g.ply")
    write_ply(p, xyz_mm, [("reflectance", "ushort", k.astype(np.uint16))])
    stream = os.path.join(w, "g.bin")
    rec = os.path.join(w, "g_rec.ply")
    out = run([tmc3, "--mode=0", "--uncompressedDataPath=" + p, "--compressedStreamPath=" + stream,
               "--positionQuantizationScale=1", "--mergeDuplicatedPoints=0", "--neighbourAvailBoundaryLog2=8",
               "--reconstructedDataPath=" + rec,
               "--bitdepth=16", "--transformType=1", "--qp=4", "--attribute=reflectance"])
    m = re.search(r"reflectance[^\n]*?(\d+) B", out)
    if not m:
        return None
    # lossless check on the encoder's reconstruction: the same multiset of values
    with open(rec, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    hdr = data[:end].decode("ascii", "replace")
    lossless = None
    if "binary_little_endian" in hdr:
        props = re.findall(r"property (\w+) (\w+)", hdr)
        tmap = {"float": "<f4", "double": "<f8", "int": "<i4", "uint16": "<u2", "ushort": "<u2", "uchar": "u1",
                "int32": "<i4", "float32": "<f4", "float64": "<f8"}
        try:
            arr = np.frombuffer(data, dtype=np.dtype([(n, tmap[t]) for t, n in props]), offset=end)
            lossless = bool(np.array_equal(np.sort(arr["reflectance"].astype(np.int64)), np.sort(k)))
        except (KeyError, ValueError):
            lossless = None
    return 8.0 * int(m.group(1)) / len(k), lossless


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--lex3d", required=True)
    ap.add_argument("--tmc3")
    ap.add_argument("--max-error", type=float, default=0.02)
    ap.add_argument("scans", nargs="+", help="NAME=PATH[,extra lex3d options separated by commas]")
    a = ap.parse_args()
    rows = []
    for spec in a.scans:
        name, rest = spec.split("=", 1)
        parts = rest.split(",")
        scan, extra = parts[0], [x for x in parts[1:] if x]
        with tempfile.TemporaryDirectory() as w:
            ply = os.path.join(w, "in.ply")
            run([a.lex3d, "convert", scan, ply] + extra)
            if not os.path.exists(ply):
                cands = sorted(x for x in os.listdir(w) if x.startswith("in_") and x.endswith(".ply"))
                ply = os.path.join(w, cands[0])
            xyz, inten = read_ply(ply)
            if inten is None:
                print("%s: no intensity" % name, file=sys.stderr)
                continue
            step, k = integer_step(inten)
            xyz_mm = np.round((xyz - xyz.min(0)) * 1000.0).astype(np.int64)
            lx, n_in, n_dec, dropped = lex3d_cost(a.lex3d, scan, w, a.max_error, False, extra)
            lx_all, _, n_all, _ = lex3d_cost(a.lex3d, scan, w, a.max_error, True, extra)
            it = lx.get("intensity")
            it_all = lx_all.get("intensity")
            dr = draco_cost(w, xyz_mm, k) if k is not None else None
            gp = gpcc_cost(a.tmc3, w, xyz_mm, k) if (a.tmc3 and k is not None) else None
            rows.append((name, n_in, step, it and 8.0 * it["bytes"] / n_dec, n_dec,
                         it_all and 8.0 * it_all["bytes"] / n_all, dr, gp, it and it["representation"]))
    print("intensity, bits a coded point (lossless unless the representation says otherwise); "
          "lex3d layer at %g m, words off" % a.max_error)
    print("%-14s %8s %7s %12s %9s %14s %8s %12s  %s" % ("scan", "points", "step", "lex3d thin", "decoded",
                                                     "lex3d all pts", "Draco", "G-PCC", "lex3d representation"))
    for name, n, step, t, nd, ta, dr, gp, rep in rows:
        g = "n/a" if gp is None else "%.3f%s" % (gp[0], "" if gp[1] else " (lossy?)" if gp[1] is False else "")
        print("%-14s %8d %7s %12s %9d %14s %8s %12s  %s" % (
            name, n, "%g" % step if step else "float", "%.3f" % t if t else "n/a", nd,
            "%.3f" % ta if ta else "n/a", "%.3f" % dr if dr is not None else "n/a", g, rep or ""))


if __name__ == "__main__":
    main()
