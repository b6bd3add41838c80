#!/usr/bin/python3
"""The laser table of a spinning lidar scan, for G-PCC's angular coding (bench/rd.py).

Usage: laser_table.py CLOUD.ply [--sensor NAME] [--json]

CLOUD.ply is a PLY of float x y z in metres in the sensor frame (bench/rd.py writes one per
scan with lex3d_convert). Prints the table as one JSON line:
  {"lasers": L, "tan_theta": [...], "z0_m": [...], "phi_per_turn": [...],
   "source": "published:<name>" | "estimated", "fit_rms_mm": ..., "fit_p95_mm": ..., ...}
Each laser i is the cone z = tan_theta[i] * r + z0_m[i], r = hypot(x, y) (G-PCC's model:
lasersTheta = tan_theta, lasersZ = -z0_m in the coded units).

Estimation (unorganised clouds, no ring field): the elevations atan2(z, r) of all points
are histogrammed in 0.01 degree bins and smoothed (0.03 degree Gaussian); each local maximum
holding at least a fifth of the median maximum's points starts a laser. Then six rounds of:
every point goes to the laser whose cone is nearest in z at its range (G-PCC's own assignment
rule); lasers that took fewer than 0.3 x the median laser's points are dropped (splits of one
ring, or surfaces) and their points reassigned; each laser's (tan_theta, z0) is refitted by
least squares on its points, the worst 5 % by residual left out (twice). The laser count is
thus found from the data, not given; it can exceed the sensor's (KITTI: about 130 for 64
beams), which costs G-PCC some bits for the laser index but does not bias the fit.
phi_per_turn: per laser, 2 pi over the median azimuth step between its points in azimuth
order (missing returns make some steps multiples; the median is the single step when most
firings return). The fit residual is z minus the laser's cone at the point's range, over all
points: its RMS and 95th percentile are reported, and are the elevation error G-PCC's
predictive geometry inherits when it codes no cartesian residual.

Published tables (--sensor): hdl32e, the nominal HDL-32E elevations -30.67 ... +10.67 degrees
in 4/3 degree steps (Velodyne's manual), no vertical offsets; the residual is still measured on
the points, and the azimuth steps still come from them.
"""

import argparse
import json
import math
import sys

import numpy as np


def read_ply_xyz(path):
    """x y z of a binary little-endian or ASCII PLY with float/double x y z (vertex element first)."""
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: PLY header without end_header")
            line = line.decode("ascii", "replace").strip()
            header.append(line)
            if line == "end_header":
                break
        body = f.read()
    fmt = next(l.split()[1] for l in header if l.startswith("format"))
    n = None
    props = []
    in_vertex = False
    for l in header:
        t = l.split()
        if t and t[0] == "element":
            in_vertex = t[1] == "vertex"
            if in_vertex:
                n = int(t[2])
        elif t and t[0] == "property" and in_vertex:
            props.append((t[-1], t[1]))
    types = {"float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8", "int": "<i4", "int32": "<i4",
             "uint": "<u4", "uint32": "<u4", "short": "<i2", "int16": "<i2", "ushort": "<u2", "uint16": "<u2",
             "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1"}
    if fmt == "ascii":
        rows = body.decode("ascii").split("\n")[:n]
        a = np.array([[float(v) for v in r.split()[:len(props)]] for r in rows])
        names = [p for p, _ in props]
        return np.stack([a[:, names.index(c)] for c in "xyz"], axis=1)
    if fmt != "binary_little_endian":
        raise ValueError(f"{path}: PLY format {fmt} not read here")
    dt = np.dtype([(p, types[t]) for p, t in props])
    if len(body) < n * dt.itemsize:
        raise ValueError(f"{path}: {n} vertices need {n * dt.itemsize} bytes, {len(body)} left")
    v = np.frombuffer(body, dtype=dt, count=n)
    return np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)


def published(name):
    if name == "hdl32e":
        deg = -30.67 + np.arange(32) * (4.0 / 3.0)
        return np.tan(np.radians(deg)), np.zeros(32)
    raise ValueError(f"no published laser table for sensor {name}")


def ring_peaks(elev_deg):
    """Centres (degrees) of the elevation histogram's rings."""
    bin_w = 0.01
    lo, hi = elev_deg.min() - 0.1, elev_deg.max() + 0.1
    hist, edges = np.histogram(elev_deg, bins=max(10, int((hi - lo) / bin_w)), range=(lo, hi))
    k = np.exp(-0.5 * (np.arange(-6, 7) * bin_w / 0.03) ** 2)
    s = np.convolve(hist.astype(np.float64), k / k.sum(), mode="same")
    peaks = [i for i in range(1, len(s) - 1) if s[i] > s[i - 1] and s[i] >= s[i + 1] and s[i] > 0]
    # a ring's mass: the points within half the distance to its neighbour peaks
    centres = 0.5 * (edges[:-1] + edges[1:])
    if not peaks:
        return np.array([])
    bounds = [0] + [(a + b) // 2 for a, b in zip(peaks, peaks[1:])] + [len(s)]
    mass = np.array([hist[bounds[j]:bounds[j + 1]].sum() for j in range(len(peaks))])
    keep = mass >= 0.2 * np.median(mass)
    return centres[np.array(peaks)[keep]]


def assign(r, z, tan_t, z0):
    """Index of the laser cone nearest in z at each point's range."""
    best = np.zeros(len(r), dtype=np.int64)
    best_err = np.full(len(r), np.inf)
    for i in range(len(tan_t)):
        e = np.abs(z - (tan_t[i] * r + z0[i]))
        m = e < best_err
        best[m] = i
        best_err[m] = e[m]
    return best


def fit(xyz, sensor=None):
    r = np.hypot(xyz[:, 0], xyz[:, 1])
    z = xyz[:, 2]
    ok = r > 1e-3
    r, z, az = r[ok], z[ok], np.arctan2(xyz[ok, 1], xyz[ok, 0])
    if sensor:
        tan_t, z0 = published(sensor)
        source = f"published:{sensor}"
    else:
        centres = ring_peaks(np.degrees(np.arctan2(z, r)))
        if len(centres) < 2:
            raise ValueError("fewer than two laser rings found")
        tan_t, z0 = np.tan(np.radians(centres)), np.zeros(len(centres))
        source = "estimated"
        for rnd in range(6):
            lab = assign(r, z, tan_t, z0)
            counts = np.bincount(lab, minlength=len(tan_t))
            if rnd >= 1:
                # rings that took few points are splits of one laser or surfaces, not lasers:
                # drop them and let their points go to the neighbours
                keep = counts >= 0.3 * np.median(counts)
                if not keep.all():
                    tan_t, z0 = tan_t[keep], z0[keep]
                    lab = assign(r, z, tan_t, z0)
            for i in range(len(tan_t)):
                m = lab == i
                if m.sum() < 10:
                    continue
                ri, zi = r[m], z[m]
                for _trim in range(2):
                    a = np.vstack([ri, np.ones_like(ri)]).T
                    (t, c), *_ = np.linalg.lstsq(a, zi, rcond=None)
                    res = np.abs(zi - (t * ri + c))
                    keep_pts = res <= np.quantile(res, 0.95)
                    ri, zi = ri[keep_pts], zi[keep_pts]
                tan_t[i], z0[i] = t, c
        order = np.argsort(tan_t)
        tan_t, z0 = tan_t[order], z0[order]
    lab = assign(r, z, tan_t, z0)
    res = z - (tan_t[lab] * r + z0[lab])
    counts = np.bincount(lab, minlength=len(tan_t))
    # azimuth step per laser
    steps = []
    for i in range(len(tan_t)):
        a = np.sort(az[lab == i])
        d = np.diff(a)
        d = d[d > 1e-6]
        steps.append(float(np.median(d)) if len(d) >= 20 else math.nan)
    good = [s for s in steps if math.isfinite(s)]
    fallback = float(np.median(good)) if good else 2 * math.pi / 1024
    phi = [int(round(2 * math.pi / (s if math.isfinite(s) else fallback))) for s in steps]
    return {
        "lasers": int(len(tan_t)), "tan_theta": [float(v) for v in tan_t], "z0_m": [float(v) for v in z0],
        "phi_per_turn": phi, "source": source,
        "theta_deg_min": float(np.degrees(np.arctan(tan_t.min()))),
        "theta_deg_max": float(np.degrees(np.arctan(tan_t.max()))),
        "fit_rms_mm": float(1000 * np.sqrt(np.mean(res ** 2))),
        "fit_p95_mm": float(1000 * np.quantile(np.abs(res), 0.95)),
        "points": int(len(r)), "empty_lasers": int((counts == 0).sum()),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cloud")
    ap.add_argument("--sensor", help="use a published table (hdl32e)")
    args = ap.parse_args()
    try:
        t = fit(read_ply_xyz(args.cloud), args.sensor)
    except (OSError, ValueError) as e:
        print(f"laser_table.py: {args.cloud}: {e}", file=sys.stderr)
        sys.exit(2)
    print(json.dumps(t))


if __name__ == "__main__":
    main()
