#!/usr/bin/env python3
"""Python module against the command on the same work: a scan compressed with a residual
layer and decompressed, median wall time of RUNS runs each.

  command: lex3d compress SCAN -o M --max-error E, then lex3d decompress M -o OUT.bin
  Python:  numpy reads SCAN, lex3d.compress (points and intensity), lex3d.decompress (with
           the intensities), numpy writes OUT.bin
           (in one process; the import is timed once, apart)

Usage: bench/python_roundtrip.py [--build build] [--scan SCAN.bin] [--max-error 0.014] [--runs 5]
Needs the module built (build/python/package) and a KITTI-layout .bin (x y z intensity);
the default scan is ../shared/data/kitti00/000000.bin, else samples/kitti00_000000.bin."""

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=str(ROOT / "build"))
    default_scan = ROOT.parent / "shared/data/kitti00/000000.bin"
    if not default_scan.exists():
        default_scan = ROOT / "samples/kitti00_000000.bin"
    ap.add_argument("--scan", default=str(default_scan))
    ap.add_argument("--max-error", type=float, default=0.014)
    ap.add_argument("--runs", type=int, default=5)
    a = ap.parse_args()
    cli = pathlib.Path(a.build) / "lex3d"
    sys.path.insert(0, str(pathlib.Path(a.build) / "python/package"))
    t = time.perf_counter()
    import numpy as np
    import lex3d
    import_s = time.perf_counter() - t

    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        model, out_cli, out_py = tmp / "m.lex3dm", tmp / "cli.bin", tmp / "py.bin"
        cli_times, py_times = [], []
        for _ in range(a.runs):
            t = time.perf_counter()
            subprocess.run([str(cli), "compress", a.scan, "-o", str(model), "--max-error", str(a.max_error)],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            subprocess.run([str(cli), "decompress", str(model), "-o", str(out_cli)],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            cli_times.append(time.perf_counter() - t)

            t = time.perf_counter()
            raw = np.fromfile(a.scan, dtype="<f4").reshape(-1, 4)
            keep = np.isfinite(raw[:, :3]).all(axis=1) & (raw[:, :3] != 0).any(axis=1)
            data = lex3d.compress(raw[keep, :3], raw[keep, 3], max_error=a.max_error)
            back, fields = lex3d.decompress(data, attributes=True)
            np.hstack([back, fields["intensity"][:, None]]).tofile(out_py)
            py_times.append(time.perf_counter() - t)
        same = data == model.read_bytes()
    cli_s, py_s = statistics.median(cli_times), statistics.median(py_times)
    print(f"scan {a.scan}: {int(keep.sum())} points, max error {a.max_error} m, {len(data)} bytes "
          f"({8 * len(data) / keep.sum():.3f} bits a point), same bytes as the command: {same}")
    print(f"command  compress + decompress: median {cli_s * 1e3:.0f} ms of {a.runs} "
          f"(min {min(cli_times) * 1e3:.0f})")
    print(f"python   compress + decompress: median {py_s * 1e3:.0f} ms of {a.runs} "
          f"(min {min(py_times) * 1e3:.0f}); import lex3d + numpy {import_s * 1e3:.0f} ms once")
    print(f"python / command: {py_s / cli_s:.2f} (goal <= 1.2)")


if __name__ == "__main__":
    main()
