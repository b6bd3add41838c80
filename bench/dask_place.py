#!/usr/bin/env python3
"""The sharded place database on a Dask LocalCluster, measured on balm (89 scans).

1. One alphabet learned once (lex3d.learn_alphabet on 5 evenly spaced scans), then the shards
   built on a LocalCluster of 1 and of 2 workers (one thread each): wall time, worker CPU,
   bytes sent to the workers.
2. The same scans as one database (lex3d.PlaceDatabase.build, in this process, then saved and
   opened as a file), and the queries 000100-000176 (poses given, --max-distance 8, as
   bench/place_scale.sh) on it and on the shards (2 workers): median and 95th-percentile query
   time, both including the description of the query scan, the sharded one split into its
   stages, bytes a query sends to and gets back from the workers (pickled payloads), and
   whether every answer equals the one database's (names, scores, transforms; bit for bit).

Usage: PYTHONPATH=build/python/package bench/dask_place.py [--shards 2] [--data ../shared/data/balm]
"""

import argparse
import os
import pathlib
import statistics
import sys
import tempfile
import time

import numpy as np


def percentile(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(round(q * (len(v) - 1))))]


def main():
    root = pathlib.Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(root.parent / "shared" / "data" / "balm"))
    ap.add_argument("--shards", type=int, default=2)
    ap.add_argument("--workers", default="1,2", help="LocalCluster sizes to build with")
    args = ap.parse_args()
    data = pathlib.Path(args.data)
    if not (data / "poses.txt").is_file():
        print(f"needs {data} (balm scans and poses.txt)", file=sys.stderr)
        return 1
    import lex3d
    import lex3d.dask
    from distributed import Client, LocalCluster
    from lex3d.dask import _place

    scans = sorted(str(p) for p in data.glob("*.bin"))
    poses = _place.read_poses(str(data / "poses.txt"), len(scans))
    out = pathlib.Path(tempfile.mkdtemp(prefix="lex3d_dask_place_"))
    t = time.perf_counter()
    alphabet = lex3d.learn_alphabet([scans[j * len(scans) // 5] for j in range(5)], iterations=200, threads=1, seed=1)
    learn_s = time.perf_counter() - t
    (out / "a.lex3da").write_bytes(alphabet)
    print(f"balm: {len(scans)} scans; alphabet learned once in {learn_s:.1f} s ({len(alphabet)} bytes)")

    t = time.perf_counter()
    whole = lex3d.PlaceDatabase.build(scans, poses=list(poses), alphabet=alphabet)
    whole_build_s = time.perf_counter() - t
    whole.save(out / "whole.lex3dp")
    whole = lex3d.PlaceDatabase.open(out / "whole.lex3dp")
    print(f"one database in this process: {whole_build_s:.1f} s, {os.path.getsize(out / 'whole.lex3dp')} bytes")

    client = None
    for w in (int(x) for x in args.workers.split(",")):
        cluster = LocalCluster(n_workers=w, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=":0")
        client = Client(cluster)
        folder = out / f"shards_{w}"
        # Poses as the one database had them: a pose list file beside the shards.
        np.savetxt(out / "poses.txt", poses[:, :3, :].reshape(len(scans), 12))
        s = lex3d.dask.build_place_shards(scans, folder, client=client, shards=args.shards, poses=out / "poses.txt",
                                          alphabet=out / "a.lex3da")
        print(f"{w} worker(s), {s['shards']} shards: build {s['build_s']:.1f} s wall, worker CPU {s['cpu_s']:.1f} s, "
              f"{s['bytes']} bytes of shards, sent to workers {s['bytes_to_workers']} bytes")
        if w != max(int(x) for x in args.workers.split(",")):
            client.close()
            cluster.close()
    db = lex3d.dask.ShardedPlaceDatabase(folder, client)
    print(f"opened {len(db.shards)} shards in {db.open_s * 1000:.0f} ms: statistics to every worker "
          f"{db.bytes_to_workers} bytes, back {db.bytes_from_workers} bytes")
    queries = [i for i, p in enumerate(scans) if int(pathlib.Path(p).stem) >= 100]
    one_ms, sharded_ms, stage = [], [], {"prepare_s": [], "retrieve_s": [], "verify_s": []}
    sent, back, qbytes, same = [], [], [], 0
    for i in queries:
        t = time.perf_counter()
        a = whole.query(scans[i], pose=poses[i], top=8, max_distance=8.0, threads=1)
        one_ms.append(1000 * (time.perf_counter() - t))
        timings = {}
        t = time.perf_counter()
        b = db.query(scans[i], pose=poses[i], top=8, max_distance=8.0, threads=1, timings=timings)
        sharded_ms.append(1000 * (time.perf_counter() - t))
        for k in stage:
            stage[k].append(1000 * timings[k])
        sent.append(timings["bytes_to_workers"])
        back.append(timings["bytes_from_workers"])
        qbytes.append(timings["query_bytes"])
        same += int([m["scan"] for m in a] == [m["scan"] for m in b] and
                    [m["score"] for m in a] == [m["score"] for m in b] and
                    all(np.array_equal(x["pose"], y["pose"]) for x, y in zip(a, b)))
    print(f"{len(queries)} queries (000100-000176, max distance 8 m): one database median {statistics.median(one_ms):.0f} ms "
          f"(p95 {percentile(one_ms, 0.95):.0f}), {len(db.shards)} shards median {statistics.median(sharded_ms):.0f} ms "
          f"(p95 {percentile(sharded_ms, 0.95):.0f})")
    print("  sharded stages, median: " + ", ".join(f"{k[:-2]} {statistics.median(v):.0f} ms" for k, v in stage.items()))
    print(f"  bytes a query: to workers median {statistics.median(sent):.0f} (the prepared query "
          f"{statistics.median(qbytes):.0f} to every shard, again to the verifying ones), back {statistics.median(back):.0f}")
    print(f"  answers equal to the one database's: {same} of {len(queries)}")
    client.close()
    return 0 if same == len(queries) else 2


if __name__ == "__main__":
    sys.exit(main())
