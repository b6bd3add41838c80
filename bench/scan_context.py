#!/usr/bin/env python3
"""Scan Context baseline for the place-recognition protocol of bench/place.sh.

Scan Context (Kim and Kim, IROS 2018) describes a scan by a polar grid around the sensor
(N_ring rings out to max_range, N_sector sectors): each bin holds the largest height of
its points; two scans are compared by the mean cosine distance of their non-empty sector
columns, minimised over column shifts (the shift gives the relative yaw). This is an
implementation written from that description, with the published parameters (20 rings,
60 sectors, 80 m); it is here so that lex3d's place recognition is measured against it on
the same scans and the same protocol as `lex3d place eval`:

  every scan queries the scans recorded at least MIN_GAP seconds earlier; the best
  candidate (smallest distance; retrieval over the whole database, no ring-key shortlist)
  is a true match when the two sensors are within RADIUS metres in the plane; a query
  counts as a positive when some database scan is within RADIUS.

Scan Context assumes a level sensor: each scan is levelled with the roll and pitch of its
ground-truth pose (the yaw is left out, so the column search still has to find it), as
lex3d's upright frames use the same poses' up direction. It gives a yaw, not a 6-DoF pose.

Usage: bench/scan_context.py DIR [--poses P] [--times T] [--min-gap 20] [--radius 4 8]
       [--max-range 80] [--rings 20] [--sectors 60] [--height 2.0]
DIR holds KITTI-layout .bin scans (frames.txt order if present); poses are world <- sensor
(KITTI poses.txt layout), one line a scan. Needs numpy.
"""

import argparse
import math
import os
import sys
import time

import numpy as np


def read_scans(d):
    frames = os.path.join(d, "frames.txt")
    if os.path.exists(frames):
        names = [l.strip() for l in open(frames) if l.strip()]
    else:
        names = sorted(f for f in os.listdir(d) if f.endswith(".bin"))
    return names, [np.fromfile(os.path.join(d, n), dtype=np.float32).reshape(-1, 4)[:, :3] for n in names]


def read_poses(path):
    rows = np.loadtxt(path).reshape(-1, 3, 4)
    return rows[:, :, :3], rows[:, :, 3]


def level(R):
    """Roll and pitch of R without its yaw: Rz(-yaw) R."""
    yaw = math.atan2(R[1, 0], R[0, 0])
    c, s = math.cos(-yaw), math.sin(-yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R


def descriptor(p, rings, sectors, max_range, height):
    r = np.hypot(p[:, 0], p[:, 1])
    keep = (r < max_range) & (r > 0)
    p, r = p[keep], r[keep]
    ring = np.minimum((r / max_range * rings).astype(int), rings - 1)
    ang = np.arctan2(p[:, 1], p[:, 0]) + math.pi
    sector = np.minimum((ang / (2 * math.pi) * sectors).astype(int), sectors - 1)
    z = np.maximum(p[:, 2] + height, 0.0)
    sc = np.zeros(rings * sectors)
    np.maximum.at(sc, ring * sectors + sector, z)
    return sc.reshape(rings, sectors)


def distance(a, b):
    """(distance, shift): mean cosine distance of the columns both scans fill, least over
    the column shifts of b."""
    sectors = a.shape[1]
    na = np.linalg.norm(a, axis=0)
    best, best_shift = 2.0, 0
    for k in range(sectors):
        bs = np.roll(b, k, axis=1)
        nb = np.linalg.norm(bs, axis=0)
        both = (na > 0) & (nb > 0)
        if not both.any():
            continue
        cos = (a[:, both] * bs[:, both]).sum(axis=0) / (na[both] * nb[both])
        d = float(np.mean(1.0 - cos))
        if d < best:
            best, best_shift = d, k
    return best, best_shift


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dir")
    ap.add_argument("--poses")
    ap.add_argument("--times")
    ap.add_argument("--min-gap", type=float, default=20.0)
    ap.add_argument("--radius", type=float, nargs="+", default=[4.0, 8.0])
    ap.add_argument("--max-range", type=float, default=80.0)
    ap.add_argument("--rings", type=int, default=20)
    ap.add_argument("--sectors", type=int, default=60)
    ap.add_argument("--height", type=float, default=2.0, help="added to z so that bins hold positive heights")
    a = ap.parse_args()
    names, clouds = read_scans(a.dir)
    R, t = read_poses(a.poses or os.path.join(a.dir, "poses.txt"))
    times = np.loadtxt(a.times or os.path.join(a.dir, "times.txt"))
    if not (len(R) == len(names) == len(times)):
        sys.exit(f"scan_context.py: {len(names)} scans, {len(R)} poses, {len(times)} times")
    t0 = time.perf_counter()
    desc = [descriptor(c @ level(R[i]).T, a.rings, a.sectors, a.max_range, a.height) for i, c in enumerate(clouds)]
    t_desc = (time.perf_counter() - t0) / len(clouds)
    order = np.argsort(times, kind="stable")
    recs = []  # (query, match, distance, shift, nearest planar distance)
    t0 = time.perf_counter()
    for q in order:
        db = [j for j in order if times[j] <= times[q] - a.min_gap]
        if not db:
            continue
        best = min((distance(desc[q], desc[j]) + (j,) for j in db), key=lambda x: x[0])
        nearest = min(np.hypot(*(t[q][:2] - t[j][:2])) for j in db)
        recs.append((q, best[2], best[0], best[1], nearest))
    t_query = (time.perf_counter() - t0) / max(len(recs), 1)
    print(f"Scan Context ({a.rings} rings x {a.sectors} sectors, {a.max_range:g} m): {len(recs)} queries, "
          f"min gap {a.min_gap:g} s; {1000 * t_desc:.1f} ms a descriptor, {1000 * t_query:.1f} ms a query "
          f"(Python/numpy, brute force)")
    for radius in a.radius:
        def planar(q, m):
            return float(np.hypot(*(t[q][:2] - t[m][:2])))
        pos = sum(1 for r in recs if r[4] <= radius)
        # Thresholds at every distance reached: accept when distance <= threshold.
        best_f1, rec_p1, curve = 0.0, 0.0, []
        for thr in sorted({r[2] for r in recs}):
            acc = [r for r in recs if r[2] <= thr]
            tp = sum(1 for r in acc if planar(r[0], r[1]) <= radius)
            fp = len(acc) - tp
            pr = tp / (tp + fp) if acc else 1.0
            rc = tp / pos if pos else 0.0
            if pr + rc > 0:
                best_f1 = max(best_f1, 2 * pr * rc / (pr + rc))
            if fp == 0:
                rec_p1 = max(rec_p1, rc)
            curve.append((thr, pr, rc))
        # Yaw error of the true top-1 matches (shift of k sectors: b turned by k * 360/sectors).
        yaw_err = []
        for q, m, d, k, _ in recs:
            if planar(q, m) > radius:
                continue
            yq = math.atan2(R[q][1, 0], R[q][0, 0])
            ym = math.atan2(R[m][1, 0], R[m][0, 0])
            truth = math.degrees(yq - ym)
            est = -k * 360.0 / a.sectors
            yaw_err.append(abs((est - truth + 180.0) % 360.0 - 180.0))
        top1 = sum(1 for r in recs if r[4] <= radius and planar(r[0], r[1]) <= radius)
        print(f"radius {radius:g} m: {pos} queries with a revisit; top-1 within the radius for {top1} of them; "
              f"max F1 {best_f1:.3f}; recall at 100% precision {rec_p1:.3f}; "
              f"median yaw error of true top-1 matches {np.median(yaw_err) if yaw_err else float('nan'):.1f} deg "
              f"(sector {360.0 / a.sectors:.0f} deg)")


if __name__ == "__main__":
    main()
