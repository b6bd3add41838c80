"""lex3d-dask (python3 -m lex3d.dask) compress|learn SCAN|FOLDER|@LIST... -o OUT [options]
          lex3d-dask place build SCAN|FOLDER|@LIST... -o DIR --shards N | place query DIR SCAN...

Runs lex3d's work over many scans on a Dask cluster (--scheduler ADDRESS, or a LocalCluster of
--workers processes on this machine). compress writes OUT_000.lex3dm ... (the files `lex3d
compress SCANS --alphabet A -o OUT` writes; a raw capture, a ROS bag or a sequence file counts as
its scans, read by this process and sent to the workers), OUT.manifest.jsonl and, when it learns one, the
alphabet; learn writes the alphabet `lex3d learn SCANS -o OUT` writes; place build writes DIR/shard_000.lex3dp, ...
(consecutive scan ranges, one alphabet) and DIR/manifest.json, and place query answers as one
database of all the scans would.
Exit codes: 0 done, 1 usage, 2 bad data (compress: a scan or more could not be coded, the
others are and the manifest names the failed ones; learn: a scan could not be read), 3 I/O
(an output folder, the scheduler).
"""

import argparse
import json
import os
import sys

from ._compress import CompressError, compress


class _Parser(argparse.ArgumentParser):
    """argparse with lex3d's exit code for a usage error (1; argparse's own 2 means bad data here)."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(1, f"{self.prog}: error: {message}\n")


# The bound --max-error auto gives, as `lex3d compress` (apps/cmd_compress.cpp): 1 cm.
AUTO_MAX_ERROR = 0.01


def _cluster_options(c):
    c.add_argument("--scheduler", help="address of a running scheduler (tcp://host:8786); default: a LocalCluster")
    c.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes of the LocalCluster (default: the CPUs), one thread each")
    c.add_argument("--timeout", type=float, default=10.0, help="seconds to reach the scheduler")
    c.add_argument("--no-progress", action="store_true")
    c.add_argument("--json", action="store_true", help="the summary as one JSON object on stdout")


def _read_options(c):
    """How captures and bags are read, as `lex3d compress` reads them."""
    c.add_argument("--metadata", help="a capture's Ouster metadata JSON or Velodyne calibration, or the JSON a bag's "
                                      "Ouster packets need (default: beside the capture)")
    c.add_argument("--topic", help="the topic of a ROS bag to read (default: its only point cloud topic)")
    c.add_argument("--single-return", action="store_true", help="a dual-return capture's first returns only")
    c.add_argument("--sensor-model", help="read a Velodyne capture as this model (vlp16, puck-hires, hdl32e, vlp32c, hdl64e)")


def _read_kw(args):
    return {"metadata": args.metadata, "topic": args.topic, "single_return": args.single_return,
            "sensor_model": args.sensor_model}


def _parser():
    p = _Parser(prog=os.path.basename(sys.argv[0]) if sys.argv[0].endswith("lex3d-dask") else "python3 -m lex3d.dask", description=__doc__.split("\n\n")[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    c = sub.add_parser("compress", help="code scans with one shared alphabet on a Dask cluster")
    c.add_argument("inputs", nargs="+", help="scan files, folders of scans, or @LIST (one path a line)")
    c.add_argument("-o", "--output", required=True, help="OUT.lex3dm: OUT_000.lex3dm, ... for several scans")
    c.add_argument("--alphabet", help="reuse this alphabet file (nothing is learned)")
    c.add_argument("--save-alphabet", help="where the learned alphabet goes (default OUT.lex3da)")
    c.add_argument("--learn-scans", type=int, default=5, help="learn on this many evenly spaced scans (default 5)")
    c.add_argument("--iterations", type=int, default=400, help="candidate words drawn when learning")
    c.add_argument("--seed", type=int, help="seed of the learner")
    c.add_argument("--max-error", default="auto",
                   help="residual-layer bound, metres; auto (the default, as lex3d compress): 1 cm, "
                        "or the bound --target-bpp finds; none: words alone")
    c.add_argument("--target-bpp", type=float, help="bits a point each file should fit")
    c.add_argument("--words", choices=["on", "off", "auto"])
    c.add_argument("--layer-coding", choices=["auto", "spherical", "voxel", "laser", "acquisition", "lattice"], default="auto")
    c.add_argument("--keep-all-points", action="store_true")
    c.add_argument("--fast", action="store_true", help="sensor-rate encoding, as lex3d compress --fast")
    c.add_argument("--objective", choices=["bound", "mse"], default="bound",
                   help="the fewest bits within the bound (bound, the default) or for the mean squared error "
                        "within it (mse), as lex3d compress --objective")
    c.add_argument("--threads", type=int, default=1, help="threads a scan (default 1; the bytes do not depend on it)")
    c.add_argument("--manifest", help="default OUT.manifest.jsonl")
    _read_options(c)
    _cluster_options(c)
    ln = sub.add_parser("learn", help="learn one alphabet over many scans on a Dask cluster")
    ln.add_argument("inputs", nargs="+", help="scan files, folders of scans, or @LIST (one path a line)")
    ln.add_argument("-o", "--output", required=True, help="the alphabet file to write (.lex3da)")
    ln.add_argument("--iterations", type=int, default=400, help="candidate words drawn at most (as lex3d learn)")
    ln.add_argument("--patience", type=int, default=100, help="stop after this many rejections in a row")
    ln.add_argument("--seed", type=int, default=1, help="seed of the candidate order")
    ln.add_argument("--word-radius", type=float, default=0.0, help="metres; 0 derives it from the first scan")
    ln.add_argument("--threads", type=int, default=1, help="threads a worker (the alphabet does not depend on it)")
    _read_options(ln)
    _cluster_options(ln)
    pl = sub.add_parser("place", help="a sharded place database: build shards on the workers, query them all")
    psub = pl.add_subparsers(dest="place_command", required=True, parser_class=_Parser)
    pb = psub.add_parser("build", help="build place database shards of consecutive scan ranges")
    pb.add_argument("inputs", nargs="+", help="scan files, folders of scans, or @LIST (one path a line)")
    pb.add_argument("-o", "--output", required=True, help="folder of the shards, the alphabet and manifest.json")
    pb.add_argument("--shards", type=int, help="this many shards of nearly equal size")
    pb.add_argument("--scans-per-shard", type=int, help="shards of this many scans (the last may hold fewer)")
    pb.add_argument("--alphabet", help="the alphabet file every shard uses (default: learned once)")
    pb.add_argument("--poses", help="world <- sensor poses, one line of 12 numbers a scan (KITTI layout)")
    pb.add_argument("--learn-scans", type=int, default=5, help="learn on this many evenly spaced scans (default 5)")
    pb.add_argument("--iterations", type=int, default=200, help="candidate words drawn when learning (default 200)")
    pb.add_argument("--seed", type=int, help="seed of the learner")
    _read_options(pb)
    _cluster_options(pb)
    pq = psub.add_parser("query", help="query every shard; the answer of one database of all the scans")
    pq.add_argument("database", help="the folder place build wrote")
    pq.add_argument("scans", nargs="+", help="query scan files")
    pq.add_argument("--top", type=int, default=3, help="matches printed a query (default 3)")
    pq.add_argument("--top-k", type=int, default=8, help="candidates verified (default 8, as lex3d place)")
    pq.add_argument("--max-distance", type=float, help="metres: reject transforms that put the sensors farther apart")
    pq.add_argument("--ground-vehicle", action="store_true")
    _read_options(pq)
    _cluster_options(pq)
    return p


def _client(args):
    """A client of the scheduler given, or of a new LocalCluster on loopback; (client, cluster)."""
    from distributed import Client, LocalCluster
    if args.scheduler:
        try:
            return Client(args.scheduler, timeout=f"{args.timeout}s"), None
        except (OSError, TimeoutError, ValueError) as e:
            raise CompressError(3, f"cannot reach the Dask scheduler at {args.scheduler}: {e}") from None
    if args.workers < 1:
        raise CompressError(1, f"--workers must be at least 1, got {args.workers}")
    cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=":0")
    client = Client(cluster)
    if not args.no_progress:
        print(f"lex3d-dask: a LocalCluster of {args.workers} workers; dashboard {client.dashboard_link}", file=sys.stderr)
    return client, cluster


def _check_alphabet(args):
    """An --alphabet given is read and decoded before any cluster starts (read_alphabet_file)."""
    if getattr(args, "alphabet", None):
        from ._files import read_alphabet_file
        read_alphabet_file(args.alphabet)


def _run_job(args, job, interrupted_message):
    """Checks the --alphabet given (_check_alphabet), then runs job(client) on the cluster of
    args (_client), then closes the client and any LocalCluster; (exit code, the job's summary
    or None). A CompressError is printed as one line and gives its code; Ctrl-C prints
    "interrupted (interrupted_message)" and gives 130."""
    client = cluster = None
    try:
        _check_alphabet(args)
        client, cluster = _client(args)
        return 0, job(client)
    except CompressError as e:
        print(f"lex3d-dask: {e}", file=sys.stderr)
        return e.code, None
    except KeyboardInterrupt:
        print(f"lex3d-dask: interrupted ({interrupted_message})", file=sys.stderr)
        return 130, None
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def _learn_main(args):
    from ._learn import learn
    code, summary = _run_job(args, lambda client: learn(
        args.inputs, args.output, client=client, iterations=args.iterations, patience=args.patience, seed=args.seed,
        word_radius=args.word_radius, threads=args.threads, progress=not args.no_progress and sys.stderr.isatty(),
        **_read_kw(args)),
        "no alphabet written")
    if code:
        return code
    for line in summary["notes"]:
        print(f"lex3d-dask: {line}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
        return 0
    s = summary
    print(f"learned {s['words']} words ({s['word_points']} points, radius {s['word_radius_m']:.3f} m) from "
          f"{s['scans']} scans, {s['points']} points, on {s['workers']} workers in {s['wall_s']:.1f} s "
          f"(prepare {s['prepare_s']:.1f} s, BIC loop {s['learn_s']:.1f} s)")
    print(f"  candidates {s['accepted']} accepted, {s['rejected']} rejected; BIC {s['bic_initial']:.6g} -> "
          f"{s['bic_final']:.6g}")
    print(f"  worker CPU {s['worker_cpu_s']:.1f} s, worker peak memory {s['worker_peak_rss_mb']:.0f} MB, driver peak "
          f"memory {s['driver_peak_rss_mb']:.0f} MB, sent to workers {s['bytes_to_workers']} bytes, returned "
          f"{s['bytes_from_workers']} bytes" + (f", {s['rebuilt_shards']} shards rebuilt" if s["rebuilt_shards"] else ""))
    print(f"  wrote {s['alphabet']}")
    return 0


def _place_build(args, client):
    from . import _place
    s = _place.build(args.inputs, args.output, client=client, shards=args.shards,
                     scans_per_shard=args.scans_per_shard, alphabet=args.alphabet, poses=args.poses,
                     learn_scans=args.learn_scans, iterations=args.iterations, seed=args.seed, **_read_kw(args))
    if args.json:
        print(json.dumps(s))
    else:
        print(f"{s['scans']} scans in {s['shards']} shards on {s['workers']} workers in {s['wall_s']:.1f} s "
              f"(learning {s['learn_s']:.1f} s, shards {s['build_s']:.1f} s, CPU {s['cpu_s']:.1f} s): "
              f"{s['bytes']} bytes; sent to workers {s['bytes_to_workers']} bytes")
        print(f"  manifest {s['manifest']}")


def _queries(paths, read_kw):
    """(name, scan) of every query: a file of one cloud is its path; a capture's, a bag's or a
    sequence file's scans are each a query of their own, as `lex3d place query` takes them."""
    import lex3d
    for path in paths:
        if not lex3d.holds_scans(path):
            yield path, path
            continue
        try:
            for scan in lex3d.scans(path, **{k: v for k, v in read_kw.items() if v}):
                yield scan.name, scan
        except (ValueError, OSError) as e:
            raise CompressError(3 if isinstance(e, OSError) else 2, str(e) if path in str(e) else f"{path}: {e}") from None


def _place_query(args, client):
    from . import _place
    db = _place.ShardedPlaceDatabase(args.database, client)
    out = []
    for name, scan in _queries(args.scans, _read_kw(args)):
        timings = {}
        try:
            matches = db.query(scan, top=args.top, top_k=args.top_k, max_distance=args.max_distance,
                               ground_vehicle=args.ground_vehicle, timings=timings)
        except (ValueError, OSError) as e:
            raise CompressError(3 if isinstance(e, OSError) else 2,
                                str(e) if name in str(e) else f"{name}: {e}") from None
        if args.json:
            out.append({"query": name, "timings": timings,
                        "matches": [dict(m, pose=m["pose"].tolist()) for m in matches]})
            continue
        best = matches[0] if matches else None
        print(f"{name}: " + (f"{best['scan']} score {best['score']:.3f}" + ("" if best["accepted"] else " (not accepted)")
                             if best else "no candidate") +
              f"  [{1000 * (timings['retrieve_s'] + timings['verify_s']):.0f} ms on {len(db.shards)} shards]")
        for m in matches:
            t = m["pose"][:3, 3]
            print(f"  {m['scan']:<24} score {m['score']:.3f} inliers {m['inliers']:>3} similarity "
                  f"{m['similarity']:.3f} t [{t[0]:.2f} {t[1]:.2f} {t[2]:.2f}]" + ("" if m["valid"] else " invalid"))
    if args.json:
        print(json.dumps(out))


def _place_main(args):
    from . import _place
    if args.place_command == "build":
        try:
            _place.check_shard_options(args.shards, args.scans_per_shard)  # usage errors before any cluster
        except CompressError as e:
            print(f"lex3d-dask: {e}", file=sys.stderr)
            return e.code
        return _run_job(args, lambda client: _place_build(args, client), "no shard written")[0]
    return _run_job(args, lambda client: _place_query(args, client), "the remaining queries not run")[0]


def main(argv=None):
    args = _parser().parse_args(argv)
    if args.command == "learn":
        return _learn_main(args)
    if args.command == "place":
        return _place_main(args)
    options = {"layer_coding": args.layer_coding, "threads": args.threads}
    explicit_error = args.max_error not in ("auto", "none")
    if explicit_error:
        try:
            args.max_error = float(args.max_error)
        except ValueError:
            print(f'lex3d-dask: --max-error must be "auto", "none" or metres, got "{args.max_error}"', file=sys.stderr)
            return 1
    elif args.max_error == "auto" and args.target_bpp is None:
        args.max_error = AUTO_MAX_ERROR
    else:
        args.max_error = None
    # As lex3d compress: with an alphabet given or saved, the words are tried with the layer
    # and kept where they make a scan's file smaller.
    if args.words is None and (args.alphabet or args.save_alphabet) and \
            (args.max_error is not None or args.target_bpp is not None):
        args.words = "auto"
    for name in ("max_error", "target_bpp", "words"):
        if getattr(args, name) is not None:
            options[name] = getattr(args, name)
    if args.keep_all_points:
        options["keep_all_points"] = True
    if args.fast:
        options["fast"] = True
    if args.objective != "bound":
        options["objective"] = args.objective
    if explicit_error and args.target_bpp is not None:
        print("lex3d-dask: give --max-error or --target-bpp, not both", file=sys.stderr)
        return 1
    code, summary = _run_job(args, lambda client: compress(
        args.inputs, args.output, client=client, alphabet=args.alphabet, save_alphabet=args.save_alphabet,
        learn_scans=args.learn_scans, iterations=args.iterations, seed=args.seed, manifest=args.manifest,
        progress=not args.no_progress and sys.stderr.isatty(), **_read_kw(args), **options),
        "no partial output files; the manifest is not written")
    if code:
        return code
    for line in summary["notes"] + summary["failures"]:
        print(f"lex3d-dask: {line}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    else:
        s = summary
        print(f"{s['ok']} of {s['scans']} scans coded on {s['workers']} workers ({s['threads']} threads) in "
              f"{s['wall_s']:.1f} s ({s['scans_per_s']:.2f} scans/s; learning {s['learn_s']:.1f} s"
              + (f"; counting the scans of captures, bags and sequences before: {s['survey_s']:.1f} s" if s["survey_s"] >= 0.05 else "")
              + "): "
              f"{s['points']} points, {s['bytes']} bytes, {s['bits_per_point']:.3f} bits a point")
        print(f"  CPU {s['cpu_s']:.1f} s (median {s['cpu_s_median'] * 1000:.0f} ms a scan), worker peak memory "
              f"{s['worker_peak_rss_mb']:.0f} MB, sent to workers {s['bytes_to_workers']} bytes, "
              f"returned {s['bytes_from_workers']} bytes")
        print(f"  manifest {s['manifest']}" + (f", alphabet {s['alphabet']}" if s["alphabet"] else ""))
    if summary["failed"]:
        print(f"lex3d-dask: {summary['failed']} of {summary['scans']} scans could not be coded "
              f"(named in {summary['manifest']})", file=sys.stderr)
        return 2
    return 0
