#!/usr/bin/env python3
"""lex3d-dask compress on one long raw capture (and, with --bag, the same turns as a ROS bag)
against `lex3d compress` on the same file: the turns are read by the driver and travel to the
workers inside their tasks (lex3d/dask/_sources.py).

Protocol: a capture of TURNS turns is made from the sample VLP-16 capture (bench/long_capture.py:
its first whole turn repeated, timestamps moved on); with --bag, `lex3d convert` writes the
same turns as a PointCloud2 bag. Then, per input and per run: a LocalCluster of --workers
processes (one thread each) codes every turn (lex3d.dask.compress, timed from the call, which
counts the turns first), and `lex3d compress FILE` (every core) codes them again. Printed:
wall time and scans a second of both, the time spent counting the turns, the driver's CPU time
(this process: reading, pickling and the in-process scheduler), the bytes sent to the workers,
and whether every file is byte-identical to the command's.

Usage: PYTHONPATH=build/python/package /usr/bin/python3 bench/dask_capture.py --cli build/lex3d
       [--turns 300] [--workers 2] [--runs 2] [--max-error 0.02] [--bag]
"""

import argparse
import filecmp
import pathlib
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import lex3d.dask
from distributed import Client, LocalCluster


def cpu_s():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main():
    here = pathlib.Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", required=True, help="the lex3d command to compare with")
    ap.add_argument("--capture", default=str(here / "samples" / "vlp16_velodyne_example.pcap"))
    ap.add_argument("--turns", type=int, default=300)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--max-error", type=float, default=0.02)
    ap.add_argument("--bag", action="store_true", help="also the same turns as a ROS bag")
    a = ap.parse_args()
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="lex3d-dask-capture-"))
    try:
        capture = tmp / f"x{a.turns}.pcap"
        subprocess.run([sys.executable, str(here / "bench" / "long_capture.py"), a.capture, str(capture), str(a.turns)],
                       check=True, capture_output=True)
        inputs = [capture]
        if a.bag:
            bag = tmp / f"x{a.turns}.bag"
            subprocess.run([a.cli, "convert", str(capture), str(bag)], check=True, capture_output=True)
            inputs.append(bag)
        cluster = LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=":0")
        client = Client(cluster)
        client.run(lambda: __import__("lex3d") and None)
        for path in inputs:
            print(f"{path.name} ({path.stat().st_size / 1e6:.1f} MB), --max-error {a.max_error}, "
                  f"{a.workers} workers")
            ref = tmp / "cli"
            for run in range(a.runs):
                shutil.rmtree(ref, ignore_errors=True)
                ref.mkdir()
                t = time.perf_counter()
                subprocess.run([a.cli, "compress", str(path), "-o", str(ref / "o.lex3dm"), "--max-error",
                                str(a.max_error)], check=True, capture_output=True)
                cli_s = time.perf_counter() - t
                out = tmp / "dask"
                shutil.rmtree(out, ignore_errors=True)
                out.mkdir()
                c0, t = cpu_s(), time.perf_counter()
                s = lex3d.dask.compress([path], out / "o.lex3dm", client=client, max_error=a.max_error)
                wall, driver = time.perf_counter() - t, cpu_s() - c0
                files = sorted(p.name for p in ref.glob("o_*.lex3dm"))
                same = len(files) == s["ok"] and all(filecmp.cmp(ref / f, out / f, shallow=False) for f in files)
                print(f"  run {run + 1}: lex3d-dask {wall:.2f} s ({s['ok'] / wall:.1f} scans/s; counting the "
                      f"scans {s['survey_s']:.2f} s), lex3d compress {cli_s:.2f} s; {s['ok']} of {s['scans']} scans, "
                      f"driver CPU {driver:.2f} s ({1000 * driver / max(1, s['scans']):.1f} ms a scan), "
                      f"sent to workers {s['bytes_to_workers'] / 1e6:.0f} MB; files identical: {same}")
        client.close()
        cluster.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
