#!/usr/bin/env python3
"""Distributed compression, 1 vs 2 workers (python3 -m lex3d.dask's code path), on a folder
of scans (default: the shared balm sequence, 89 scans).

Protocol: one alphabet is learned beforehand on 5 evenly spaced scans (lex3d.learn_alphabet,
not timed) and given to every run, so each run only codes. Per worker count: a LocalCluster of
N processes with one thread each on loopback, lex3d imported on every worker first, then
lex3d.dask.compress over all scans (one thread a scan). Printed: wall time, speed-up and
efficiency against 1 worker, the per-scan CPU time (median, from the workers), the workers'
peak resident memory, the driver's peak resident memory (it hosts the scheduler too), the bytes
sent to and returned by workers (pickled task arguments and manifest rows, plus the alphabet once
a worker) and whether the files are byte-identical between runs and to `lex3d compress SCANS
--alphabet A` (single process, two scans side by side, also timed) when --cli is given.
Then the same per-scan costs projected to 100 workers and 1e6 scans (a projection, labelled).

Usage: PYTHONPATH=build/python/package /usr/bin/python3 bench/dask_scaling.py [--data DIR]
       [--cli build/lex3d] [--workers 1 2] [--max-error E] [--repeat R]
"""

import argparse
import os
import pathlib
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import lex3d
import lex3d.dask
from distributed import Client, LocalCluster


def main():
    here = pathlib.Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(here.parent / "shared" / "data" / "balm"))
    ap.add_argument("--cli")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--max-error", type=float)
    ap.add_argument("--repeat", type=int, default=1, help="the list of scans this many times (driver memory)")
    a = ap.parse_args()
    scans = lex3d.dask.expand_inputs([a.data]) * a.repeat
    n = len(scans)
    options = {"max_error": a.max_error, "words": "on"} if a.max_error else {}
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="lex3d-dask-bench-"))
    try:
        k = 5
        t = time.perf_counter()
        # In a process of its own, so the driver's peak memory below is the driver's alone.
        subprocess.run([sys.executable, "-c", "import sys, lex3d; open(sys.argv[1], 'wb').write("
                        "lex3d.learn_alphabet(sys.argv[2:], iterations=200))", str(tmp / "a.lex3da"),
                        *[scans[j * n // k] for j in range(k)]], check=True)
        alphabet = (tmp / "a.lex3da").read_bytes()
        print(f"{n} scans from {a.data}; alphabet learned on {k} scans in {time.perf_counter() - t:.1f} s "
              f"({len(alphabet)} bytes); options {options or 'default (words only)'}; "
              f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
        results = {}
        for w in a.workers:
            cluster = LocalCluster(n_workers=w, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address=":0")
            client = Client(cluster)
            client.run(lambda: __import__("lex3d") and None)
            out = tmp / f"w{w}"
            out.mkdir()
            load0 = os.getloadavg()[0]
            s = lex3d.dask.compress(scans, out / "s.lex3dm", client=client, alphabet=tmp / "a.lex3da", **options)
            client.close()
            cluster.close()
            results[w] = s
            base = results[a.workers[0]]
            same = all((out / f"s_{i:03d}.lex3dm").read_bytes() ==
                       (tmp / f"w{a.workers[0]}" / f"s_{i:03d}.lex3dm").read_bytes() for i in range(n))
            print(f"{w} worker(s): {s['wall_s']:.1f} s, {s['scans_per_s']:.2f} scans/s, speed-up "
                  f"{base['wall_s'] / s['wall_s']:.2f}x (efficiency {base['wall_s'] / s['wall_s'] / w * a.workers[0] * 100:.0f} %), {s['ok']}/{n} ok, {s['bits_per_point']:.3f} bits a point; CPU a scan median "
                  f"{s['cpu_s_median'] * 1000:.0f} ms ({s['cpu_s']:.1f} s in all); worker peak RSS "
                  f"{s['worker_peak_rss_mb']:.0f} MB; to workers {s['bytes_to_workers'] / n:.0f} B a scan "
                  f"(+ alphabet {s['alphabet_bytes']} B a worker), from workers {s['bytes_from_workers'] / n:.0f} B a scan; "
                  f"load average {load0:.1f} -> {os.getloadavg()[0]:.1f}; files identical to the first run: {same}")
            print(f"  driver peak RSS so far (scheduler included): "
                  f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
        if a.cli:
            ref = tmp / "cli"
            ref.mkdir()
            args = [a.cli, "compress", *scans, "--alphabet", str(tmp / "a.lex3da"), "-o", str(ref / "s.lex3dm")]
            if a.max_error:
                args += ["--max-error", str(a.max_error), "--words", "on"]
            else:
                args += ["--max-error", "none"]  # the command's default is a 1 cm bound; the workers code words only
            t = time.perf_counter()
            # Without the MALLOC_TRIM_THRESHOLD_ the LocalCluster put in this process's
            # environment: it also pins glibc's mmap threshold and doubles the command's time.
            env = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
            subprocess.run(args, check=True, capture_output=True, env=env)
            cli_s = time.perf_counter() - t
            same = all((ref / f"s_{i:03d}.lex3dm").read_bytes() ==
                       (tmp / f"w{a.workers[0]}" / f"s_{i:03d}.lex3dm").read_bytes() for i in range(n))
            print(f"lex3d compress (one process, 2 threads): {cli_s:.1f} s; files identical: {same}")
        w1 = results[a.workers[0]]
        cpu = w1["cpu_s_median"]
        print("PROJECTION (not measured): 100 workers, 1e6 scans, from the per-scan figures above:")
        print(f"  wall ~ {1e6 * cpu / 100 / 3600:.2f} h with a core a worker ({cpu * 1000:.0f} ms CPU a scan); "
              f"scheduler ~ {100 / cpu:.0f} scans/s (in tasks of up to 16); to workers ~ {1e6 * w1['bytes_to_workers'] / n / 1e9:.2f} GB, "
              f"from workers ~ {1e6 * w1['bytes_from_workers'] / n / 1e9:.2f} GB (plus the scans read from storage)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
