#!/usr/bin/env python3
"""Re-sample a real lidar scan as another spinning lidar would have seen it.

lex3d's sensor-geometry coding must work on lidars whose scans are not in ../shared/data
(VLP-32C, VLS-128, Hesai Pandar / OT128, HDL-64E with its per-laser offsets). This tool
takes a dense real scan, treats the surfaces it saw as the world, and casts the rays of a
target sensor into it: each target laser has its vendor elevation, azimuth offset and firing
time (bench/sensors/*.json, taken from the public calibration files named in each file's
"source"), the columns follow the sensor's azimuth step with encoder jitter, the range is
interpolated on the source scan's surface (triangles across a depth jump or a gap give no
return rather than a point in mid-air), Gaussian range noise is added and the range is
quantised to the sensor's distance resolution. The points are formed from the *reported*
azimuth, as the sensor's firmware does.

The scene detail is that of the source scan, so the figures measure how lex3d follows the
beam layout (laser table, azimuth offsets, firing time), not the target sensor's noise.

  sensor_resample.py SOURCE.bin|pcd TABLE.json OUT.bin [--ring OUT.pcd] [--shuffle]
                     [--noise 0.01] [--seed 1] [--rate 10]

SOURCE: float32 x y z (KITTI .bin with 4 floats, or 3 floats with --stride 3) or an ASCII /
binary PCD with x y z. OUT.bin: float32 x y z intensity(0) in firing order (columns, then
lasers in table order); --ring also writes a PCD with a `ring` field; --shuffle permutes
OUT.bin's points (a cloud with no order to exploit).
"""
import argparse
import json
import math
import struct
import sys

import numpy as np
from scipy.spatial import Delaunay


def read_cloud(path, stride):
    if path.endswith(".pcd"):
        with open(path, "rb") as f:
            data = f.read()
        header_end = data.index(b"DATA")
        header = data[:header_end].decode("ascii", "replace").split("\n")
        line_end = data.index(b"\n", header_end)
        kind = data[header_end:line_end].decode().split()[1]
        fields, sizes, counts, types, points = [], [], [], [], 0
        for line in header:
            tok = line.split()
            if not tok:
                continue
            if tok[0] == "FIELDS":
                fields = tok[1:]
            elif tok[0] == "SIZE":
                sizes = [int(t) for t in tok[1:]]
            elif tok[0] == "TYPE":
                types = tok[1:]
            elif tok[0] == "COUNT":
                counts = [int(t) for t in tok[1:]]
            elif tok[0] == "POINTS":
                points = int(tok[1])
        if not counts:
            counts = [1] * len(fields)
        body = data[line_end + 1:]
        if kind == "ascii":
            arr = np.loadtxt(body.decode().splitlines(), ndmin=2)
            idx = [fields.index(c) for c in "xyz"]
            return arr[:, idx].astype(np.float64)
        if kind != "binary":
            sys.exit("sensor_resample: %s: only ascii and binary PCD (convert it with lex3d convert)" % path)
        dt = np.dtype([(f, {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "u1", ("U", 2): "<u2",
                            ("U", 4): "<u4", ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4"}[(t, s)], (c,))
                       for f, s, t, c in zip(fields, sizes, types, counts)])
        rec = np.frombuffer(body[:points * dt.itemsize], dtype=dt)
        return np.stack([rec[c][:, 0].astype(np.float64) for c in "xyz"], axis=1)
    raw = np.fromfile(path, dtype="<f4")
    return raw.reshape(-1, stride)[:, :3].astype(np.float64)


def write_bin(path, xyz):
    out = np.zeros((len(xyz), 4), dtype="<f4")
    out[:, :3] = xyz
    out.tofile(path)


def write_pcd_ring(path, xyz, ring):
    rec = np.zeros(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("ring", "<u2")])
    rec["x"], rec["y"], rec["z"], rec["ring"] = xyz[:, 0], xyz[:, 1], xyz[:, 2], ring
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z ring\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\n"
              "WIDTH %d\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA binary\n" % (len(xyz), len(xyz)))
    with open(path, "wb") as f:
        f.write(header.encode())
        f.write(rec.tobytes())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("source")
    ap.add_argument("table")
    ap.add_argument("out")
    ap.add_argument("--ring", help="also write a PCD with a ring field")
    ap.add_argument("--shuffle", action="store_true")
    ap.add_argument("--noise", type=float, default=0.01, help="range noise sigma, metres")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rate", type=float, default=10.0, help="rotation rate, Hz")
    ap.add_argument("--stride", type=int, default=4, help="floats a point in a .bin source")
    ap.add_argument("--jitter", type=float, default=0.003, help="encoder jitter sigma, degrees")
    a = ap.parse_args()

    table = json.load(open(a.table))
    src = read_cloud(a.source, a.stride)
    r = np.linalg.norm(src, axis=1)
    keep = np.isfinite(r) & (r > 0.3)
    src, r = src[keep], r[keep]
    az = np.arctan2(src[:, 1], src[:, 0])
    el = np.arcsin(np.clip(src[:, 2] / r, -1, 1))

    # The source's angular spacing (median distance to the nearest neighbour in angle space)
    # bounds which triangles are surface and which span a gap.
    wrap = np.abs(az) > math.pi - 0.05
    az_all = np.concatenate([az, az[wrap] - 2 * math.pi * np.sign(az[wrap])])
    el_all = np.concatenate([el, el[wrap]])
    r_all = np.concatenate([r, r[wrap]])
    tri = Delaunay(np.stack([az_all, el_all], axis=1))
    edges = np.concatenate([tri.simplices[:, [0, 1]], tri.simplices[:, [1, 2]], tri.simplices[:, [0, 2]]])
    elen = np.hypot(az_all[edges[:, 0]] - az_all[edges[:, 1]], el_all[edges[:, 0]] - el_all[edges[:, 1]])
    max_edge = 4.0 * np.median(elen)

    rng = np.random.default_rng(a.seed)
    lasers = table["lasers"]
    columns = int(table["columns"])
    step = float(table["range_step"])
    deg_per_us = 360.0 * a.rate * 1e-6
    elev = np.radians([l["elevation_deg"] for l in lasers])
    az_off = np.radians([l["azimuth_deg"] for l in lasers])
    fire = np.array([l["fire_us"] for l in lasers])
    fire = np.radians((fire - fire.min()) * deg_per_us)
    zoff = np.array([l["z_offset"] for l in lasers])
    hoff = np.array([l["horiz_offset"] for l in lasers])

    L = len(lasers)
    col = np.arange(columns)
    reported = np.radians(np.round((col * 360.0 / columns + rng.normal(0, a.jitter, columns)) / 0.01) * 0.01)
    true_col = reported + np.radians(rng.normal(0, a.jitter / 3, columns))
    # Velodyne and Hesai report the azimuth clockwise from the front; the cloud's azimuth is
    # counter-clockwise. Rays: column c, laser l at azimuth -(reported + offset + firing advance).
    ray_az = -(true_col[:, None] + az_off[None, :] + fire[None, :])
    ray_el = np.broadcast_to(elev[None, :], ray_az.shape)
    q = np.stack([((ray_az + math.pi) % (2 * math.pi)) - math.pi, ray_el], axis=-1).reshape(-1, 2)
    simplex = tri.find_simplex(q)
    valid = simplex >= 0
    verts = tri.simplices[np.where(valid, simplex, 0)]
    T = tri.transform[np.where(valid, simplex, 0)]
    b2 = np.einsum("nij,nj->ni", T[:, :2, :], q - T[:, 2, :])
    bary = np.concatenate([b2, 1 - b2.sum(axis=1, keepdims=True)], axis=1)
    vr = r_all[verts]
    va, ve = az_all[verts], el_all[verts]
    span = np.maximum.reduce([np.hypot(va[:, i] - va[:, j], ve[:, i] - ve[:, j]) for i, j in ((0, 1), (1, 2), (0, 2))])
    jump = vr.max(axis=1) / vr.min(axis=1) > 1.0 + 8.0 * max_edge
    valid &= span <= max_edge
    rr = (bary * vr).sum(axis=1)
    # Across a depth jump the beam sees the surface of its nearest source ray.
    nearest = vr[np.arange(len(vr)), np.argmax(bary, axis=1)]
    rr = np.where(jump, nearest, rr)
    rr = rr + rng.normal(0, a.noise, rr.shape)
    rr = np.round(rr / step) * step
    valid &= rr > 0.5
    rr = rr.reshape(columns, L)
    valid = valid.reshape(columns, L)

    rep_az = -(reported[:, None] + az_off[None, :])
    ce, se = np.cos(ray_el), np.sin(ray_el)
    xy = rr * ce
    x = xy * np.cos(rep_az) - hoff[None, :] * np.sin(rep_az)
    y = xy * np.sin(rep_az) + hoff[None, :] * np.cos(rep_az)
    z = rr * se + zoff[None, :]
    pts = np.stack([x, y, z], axis=-1)[valid]
    ring = np.broadcast_to(np.arange(L)[None, :], valid.shape)[valid]
    if a.ring:
        write_pcd_ring(a.ring, pts, ring)
    if a.shuffle:
        pts = pts[rng.permutation(len(pts))]
    write_bin(a.out, pts)
    print("%s: %d of %d rays returned (%d lasers x %d columns), source %d points" %
          (a.out, len(pts), valid.size, L, columns, len(src)))


if __name__ == "__main__":
    main()
