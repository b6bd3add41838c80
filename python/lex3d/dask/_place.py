"""A sharded place database on a Dask cluster: shards built in parallel, queried in stages.

build() splits the scans into consecutive ranges and builds one place database a range on
the workers, every shard with the same alphabet (given, or learned once on one worker), and
writes a manifest (JSON) of the shards. ShardedPlaceDatabase queries every shard so that the
answer equals that of one database holding all the scans (lex3d/place/place.hpp, staged query):

1. the query scan is described once on the driver (PlaceDatabase.prepare_query: bytes);
2. every shard ranks its entries by tf-idf with the summed word statistics of all shards (the
   global idf and the entries' norms under it) and returns its top-K;
3. the driver keeps the top-K of all (score, then lower global index, as one database does);
4. the shards owning them verify them and densely align their own best (PlaceDatabase.verify);
5. the driver orders the matches as one database does, the best dense_candidates in their
   densely aligned form.
"""

import hashlib
import json
import os
import pickle
import time
import uuid

import numpy as np

from ._compress import CompressError, expand_inputs, learn_task
from ._sources import ScanSources, SourceChanged, pack, unpack
from ._files import read_alphabet_file
from ._worker import worker_malloc

MANIFEST = "manifest.json"
KIND = "lex3d-place-shards"


def _sha256(data):
    return hashlib.sha256(data).hexdigest()


def _stem(path):
    name = os.path.basename(path)
    dot = name.rfind(".")
    return name if dot <= 0 else name[:dot]


def read_poses(path, count):
    """World <- sensor poses of a KITTI pose list (12 values a line), 4x4 each; exactly `count`."""
    try:
        rows = np.loadtxt(path, ndmin=2)
    except OSError as e:
        raise CompressError(3, f"{path}: cannot read the poses: {e.strerror or e}") from None
    except ValueError as e:
        raise CompressError(2, f"{path}: not a pose list (12 numbers a line): {e}") from None
    if rows.shape[1] != 12 or not np.isfinite(rows).all():
        raise CompressError(2, f"{path}: not a pose list: {rows.shape[1]} numbers a line, 12 expected")
    if len(rows) != count:
        raise CompressError(2, f"{path}: {len(rows)} poses for {count} scans")
    poses = np.tile(np.eye(4), (count, 1, 1))
    poses[:, :3, :] = rows.reshape(-1, 3, 4)
    return poses


def check_shard_options(shards=None, scans_per_shard=None):
    """Usage errors of the shard options (exit 1), before any work."""
    if (shards is None) == (scans_per_shard is None):
        raise CompressError(1, "give --shards or --scans-per-shard (one of them)")
    if shards is not None and shards < 1:
        raise CompressError(1, f"--shards must be at least 1, got {shards}")
    if scans_per_shard is not None and scans_per_shard < 1:
        raise CompressError(1, f"--scans-per-shard must be at least 1, got {scans_per_shard}")


def shard_ranges(n, shards=None, scans_per_shard=None):
    """Consecutive [first, end) ranges of n scans: `shards` of nearly equal size, or
    `scans_per_shard` each (the last may be smaller)."""
    check_shard_options(shards, scans_per_shard)
    if shards is not None:
        if shards > n:
            raise CompressError(1, f"--shards {shards} for {n} scans: a shard needs at least one scan")
        bounds = [i * n // shards for i in range(shards + 1)]
    else:
        bounds = list(range(0, n, scans_per_shard)) + [n]
    return [(bounds[i], bounds[i + 1]) for i in range(len(bounds) - 1)]


def build_shard_task(paths, names, poses, alphabet, output, job):
    """On a worker: the place database of `paths` (or the scans pack() made) with `alphabet`
    (bytes), written to `output` (through a temporary name). Returns its entries, bytes,
    alphabet hash and CPU time."""
    import lex3d
    worker_malloc()
    cpu0 = time.process_time()
    tmp = f"{output}.{job}.tmp"
    try:
        # One thread: a Dask worker runs one task a thread it has.
        db = lex3d.PlaceDatabase.build(list(unpack(paths)), names=list(names), poses=poses, alphabet=alphabet, threads=1)
        db.save(tmp)
        os.replace(tmp, output)
    except (ValueError, OSError) as e:  # a value, not raised: the driver names it and cleans up
        return {"build_error": str(e).splitlines()[0] if str(e) else type(e).__name__}
    return {"entries": len(db), "bytes": os.path.getsize(output), "alphabet_sha256": _sha256(db.alphabet_file()),
            "cpu_s": time.process_time() - cpu0}


def _write_json_atomic(path, obj, job):
    tmp = f"{path}.{job}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(obj, f, indent=1)
            f.write("\n")
        os.replace(tmp, path)
    except OSError as e:
        try:
            os.remove(tmp)
        except OSError:
            pass
        raise CompressError(3, f"{path}: cannot write: {e.strerror or e}") from None


def _names(sources):
    """The scans' names, as `lex3d place build` gives them: a file's stem; a capture's or bag's
    k-th scan <stem>_<k> (where it holds more than one), a sequence's <stem>_<kkk>."""
    count = {}
    for path, turn, _, _ in sources.entries:
        count[path] = count.get(path, 0) + 1
    names = []
    for path, turn, _, _ in sources.entries:
        stem = _stem(path)
        if turn is None or (count[path] == 1 and not path.lower().endswith(".lex3dq")):
            names.append(stem)
        elif path.lower().endswith(".lex3dq"):
            names.append(f"{stem}_{turn:03d}")
        else:
            names.append(f"{stem}_{turn}")
    return names


def build(inputs, output, *, client, shards=None, scans_per_shard=None, alphabet=None, poses=None, learn_scans=5,
          iterations=200, seed=None, metadata=None, topic=None, single_return=False, sensor_model=None):
    """Builds a sharded place database in the folder `output`: shard_000.lex3dp, ... (consecutive
    scan ranges), the alphabet (alphabet.lex3da) and manifest.json. Returns a summary dict.
    A capture, a bag or a sequence file counts as its scans, as `lex3d place build` counts
    them: the driver reads them (ScanSources; metadata, topic, single_return, sensor_model: how)
    and each shard's task carries its scans; then at most one shard a worker is in flight."""
    import lex3d
    paths = expand_inputs(inputs)
    sources = ScanSources(paths, metadata=metadata, topic=topic, single_return=single_return,
                          sensor_model=sensor_model)
    n = len(sources)
    if n == 0:
        raise CompressError(1, "no scans given")
    bad = sources.first_error()
    if bad is not None:  # as lex3d place build: every scan is read, or nothing is built
        raise CompressError(2, bad)
    feed = sources.reader()

    def scans_of(indices):
        try:
            return feed.items(indices)
        except SourceChanged as e:
            raise CompressError(2, str(e)) from None

    ranges = shard_ranges(n, shards, scans_per_shard)
    pose_list = read_poses(poses, n) if poses else None
    names = _names(sources)
    if os.path.exists(os.path.join(output, MANIFEST)):
        raise CompressError(1, f"{output}: already holds a sharded database ({MANIFEST}); give a new folder")
    job = uuid.uuid4().hex[:12]
    wall0 = time.perf_counter()
    learn_s = 0.0
    if alphabet is not None:
        alphabet_bytes = read_alphabet_file(alphabet)
    else:
        k = min(n, max(1, learn_scans))
        sample = scans_of(j * n // k for j in range(k))
        t = time.perf_counter()
        seed_kw = {} if seed is None else {"seed": seed}
        try:
            alphabet_bytes = client.submit(learn_task, sample, iterations, seed_kw, 1, pure=False).result()
        except (ValueError, OSError) as e:
            raise CompressError(2, f"learning the alphabet: {e}") from None
        learn_s = time.perf_counter() - t
    created = not os.path.isdir(output)
    try:
        os.makedirs(output, exist_ok=True)
    except OSError as e:
        raise CompressError(3, f"{output}: cannot create the folder: {e.strerror or e}") from None
    key = f"lex3d-place-alphabet-{_sha256(alphabet_bytes)[:16]}"
    alphabet_ref = client.scatter({key: alphabet_bytes}, broadcast=True)[key]
    workers = len(client.scheduler_info().get("workers", {}))
    t = time.perf_counter()
    futures, sent = [], 0
    outputs = [os.path.abspath(os.path.join(output, f"shard_{i:03d}.lex3dp")) for i in range(len(ranges))]
    for i, (a, b) in enumerate(ranges):
        if sources.multi and i >= max(1, workers):
            # (carried scans: one shard a worker in flight, so the driver holds no more)
            from distributed import wait
            wait(futures[i - max(1, workers)])
        scans = scans_of(range(a, b))
        if sources.multi:
            scans = pack(scans)
        args = (scans, names[a:b], None if pose_list is None else pose_list[a:b], alphabet_ref, outputs[i], job)
        carried = isinstance(scans, bytes)  # (packed: counted as they travel, not pickled again)
        sent += (len(scans) + len(pickle.dumps(args[1:3])) if carried else len(pickle.dumps(args[:3]))) + \
            len(pickle.dumps(args[4:]))
        del scans
        futures.append(client.submit(build_shard_task, *args, key=f"lex3d-place-shard-{job}-{i}", pure=False))
        del args
    _settle(futures)
    results, error = [], None
    for i, fut in enumerate(futures):
        try:
            r = fut.result()
        except (ValueError, OSError) as e:
            r = {"build_error": str(e)}
        if "build_error" in r and error is None:
            error = f"shard {i} (scans {ranges[i][0]}-{ranges[i][1] - 1}): {r['build_error']}"
        results.append(r)
    build_s = time.perf_counter() - t
    if error is None and len({r["alphabet_sha256"] for r in results}) != 1:
        error = "the shards hold different alphabets"
    if error is not None:
        # No partial database: the shards this job wrote go, and the folder when it made it.
        for path in outputs:
            try:
                os.remove(path)
            except OSError:
                pass
        if created:
            try:
                os.rmdir(output)
            except OSError:
                pass
        raise CompressError(2, error)
    hashes = {r["alphabet_sha256"] for r in results}
    alphabet_path = os.path.join(output, "alphabet.lex3da")
    tmp = f"{alphabet_path}.{job}.tmp"
    try:
        with open(tmp, "wb") as f:
            f.write(alphabet_bytes)
        os.replace(tmp, alphabet_path)
    except OSError as e:
        raise CompressError(3, f"{alphabet_path}: cannot write: {e.strerror or e}") from None
    manifest = {
        "kind": KIND, "version": 1, "lex3d": lex3d.__version__, "scans": n,
        "alphabet": "alphabet.lex3da", "alphabet_sha256": hashes.pop(),
        "shards": [{"file": f"shard_{i:03d}.lex3dp", "first": a, "count": b - a, "entries": r["entries"],
                    "bytes": r["bytes"], "names": names[a:b]}
                   for i, ((a, b), r) in enumerate(zip(ranges, results))],
    }
    _write_json_atomic(os.path.join(output, MANIFEST), manifest, job)
    return {"scans": n, "shards": len(ranges), "workers": workers, "wall_s": time.perf_counter() - wall0,
            "learn_s": learn_s, "build_s": build_s, "cpu_s": sum(r["cpu_s"] for r in results),
            "bytes": sum(r["bytes"] for r in results), "alphabet_bytes": len(alphabet_bytes),
            "bytes_to_workers": sent + workers * len(alphabet_bytes), "manifest": os.path.join(output, MANIFEST)}


# Each worker process keeps the shards it opened (memory-mapped; the index alone is read).
_OPEN = {}


def _shard(path):
    import lex3d
    st = os.stat(path)
    key = (path, st.st_mtime_ns, st.st_size)
    db = _OPEN.get(key)
    if db is None:
        db = lex3d.PlaceDatabase.open(path, threads=1)  # one task a worker thread
        if len(_OPEN) >= 64:
            _OPEN.clear()
        _OPEN[key] = db
    return db


def _on_shard(f):
    """Runs f() on a worker; a bad or missing shard comes back as a value, {"shard_error":
    message, "missing": bool} (a raised error would also be logged by the worker)."""
    worker_malloc()
    try:
        return f()
    except FileNotFoundError as e:
        return {"shard_error": str(e), "missing": True}
    except (ValueError, OSError) as e:
        return {"shard_error": str(e), "missing": False}


def open_shard_task(path):
    """On a worker: the shard's entries, alphabet hash and word statistics."""
    def run():
        db = _shard(path)
        return {"entries": len(db), "alphabet_sha256": _sha256(db.alphabet_file()), "stats": db.word_statistics()}
    return _on_shard(run)


def retrieve_task(path, query, stats, top_k):
    return _on_shard(lambda: _shard(path).retrieve(query, top_k=top_k, stats=stats))


def verify_task(path, query, candidates, options):
    return _on_shard(lambda: _shard(path).verify(query, candidates, **options))


def _named(path, error):
    """One line naming the shard `path` and what is wrong with it."""
    message = str(error).splitlines()[0] if str(error) else type(error).__name__
    base = os.path.basename(path)
    return message if base in message else f"{path}: {message}"


def _settle(futures):
    """Waits for every task of a stage, so that none is left running when one shard's error
    ends the query (errors come back as values; see _on_shard)."""
    from distributed import wait
    wait(futures)


def _order(m):
    """One database's order of verified matches: valid first, then score, then lower index."""
    return (not m["valid"], -m["score"], m["index"])


def merge_verified(parts, offsets):
    """The matches of verify() parts (shard order, with their first global indices) ordered as
    one database orders them (lex3d::merge_verified)."""
    dense = max((p["dense_candidates"] for p in parts), default=0)
    matches, refined = [], {}
    for part, off in zip(parts, offsets):
        for m in part["matches"]:
            matches.append(dict(m, index=m["index"] + off))
        for m in part["refined"]:
            refined[m["index"] + off] = dict(m, index=m["index"] + off)
    matches.sort(key=_order)
    if dense:
        for i in range(min(len(matches), dense)):
            matches[i] = refined[matches[i]["index"]]
        matches.sort(key=lambda m: (not m["dense_refined"],) + _order(m))
    return matches


def merge_round(first, second, dense):
    """A second round's merged matches added to the first's, ordered as one database orders
    them (lex3d::merge_round)."""
    matches = first + second
    matches.sort(key=(lambda m: (not m["dense_refined"],) + _order(m)) if dense else _order)
    return matches


class ShardedPlaceDatabase:
    """A sharded place database (a folder build() wrote) queried on a Dask cluster.

        db = ShardedPlaceDatabase("places/", client)
        for match in db.query("scan.bin"):   # as lex3d.PlaceDatabase.query: the same answer
            print(match["scan"], match["score"], match["pose"])
    """

    def __init__(self, folder, client):
        self.folder = os.fspath(folder)
        self.client = client
        mpath = os.path.join(self.folder, MANIFEST)
        try:
            with open(mpath, encoding="utf-8") as f:
                manifest = json.load(f)
        except OSError as e:
            raise CompressError(3, f"{mpath}: cannot read the manifest: {e.strerror or e}") from None
        except ValueError as e:
            raise CompressError(2, f"{mpath}: not a JSON manifest: {e}") from None
        try:
            if manifest.get("kind") != KIND or manifest.get("version") != 1:
                raise ValueError(f"not a {KIND} manifest of version 1")
            self.shards = [(os.path.join(self.folder, s["file"]), int(s["first"]), int(s["count"]))
                           for s in manifest["shards"]]
            self.names = [name for s in manifest["shards"] for name in s["names"]]
            expected_sha = manifest["alphabet_sha256"]
            first = 0
            for path, a, count in self.shards:
                if a != first or count < 0:
                    raise ValueError(f"{os.path.basename(path)} starts at scan {a}, the shards before end at {first}")
                first += count
            if first != manifest["scans"] or len(self.names) != first:
                raise ValueError(f"the shards hold {first} scans and {len(self.names)} names, the manifest says "
                                 f"{manifest['scans']}")
        except (KeyError, TypeError, ValueError) as e:
            raise CompressError(2, f"{mpath}: {e if isinstance(e, ValueError) else 'missing or bad field ' + str(e)}") from None
        self.offsets = [a for _, a, _ in self.shards]
        t = time.perf_counter()
        futures = [client.submit(open_shard_task, os.path.abspath(p), pure=False) for p, _, _ in self.shards]
        scans, df = 0, np.zeros(0, dtype=np.uint64)
        self.bytes_from_workers = 0
        _settle(futures)
        for i, ((path, _, count), fut) in enumerate(zip(self.shards, futures)):
            r = self._result(fut, i)
            if r["entries"] != count:
                raise CompressError(2, f"{path}: shard holds {r['entries']} scans, the manifest says {count}")
            if r["alphabet_sha256"] != expected_sha:
                raise CompressError(2, f"{path}: shard's alphabet differs from the manifest's")
            n, d = r["stats"]
            scans += n
            if len(d) > len(df):
                df = np.concatenate([df, np.zeros(len(d) - len(df), dtype=np.uint64)])
            df[:len(d)] += d
            self.bytes_from_workers += len(pickle.dumps(r))
        self.open_s = time.perf_counter() - t
        self.stats = (scans, df)
        key = f"lex3d-place-stats-{uuid.uuid4().hex[:12]}"
        self._stats_ref = client.scatter({key: self.stats}, broadcast=True)[key]
        self.bytes_to_workers = len(client.scheduler_info().get("workers", {})) * len(pickle.dumps(self.stats))
        # The driver describes query scans with the shards' alphabet and storage (shard 0's index only).
        import lex3d
        try:
            self._local = lex3d.PlaceDatabase.open(self.shards[0][0])
        except (ValueError, OSError) as e:
            raise CompressError(2, f"{self.shards[0][0]}: shard cannot be opened: {e}") from None

    def __len__(self):
        return len(self.names)

    def prepare_query(self, scan, *, pose=None, gravity=None, model_alphabet=None):
        """The query scan described once (bytes for every shard)."""
        return self._local.prepare_query(scan, pose=pose, gravity=gravity, model_alphabet=model_alphabet)

    def query(self, scan, *, pose=None, gravity=None, top=5, max_distance=None, ground_vehicle=False,
              top_k=8, more_candidates=8, threads=1, model_alphabet=None, timings=None):
        """The verified candidates, best first (at most `top`): dicts as lex3d.PlaceDatabase.query
        gives, "index" the scan's index in the whole; equal to one database of all the scans.
        `timings` (a dict) receives prepare_s, retrieve_s, verify_s and the bytes sent and returned."""
        if top < 1:
            raise ValueError(f"top must be at least 1, got {top}")
        t0 = time.perf_counter()
        q = self.prepare_query(scan, pose=pose, gravity=gravity, model_alphabet=model_alphabet)
        t1 = time.perf_counter()
        # top_k candidates, and the next more_candidates for a second round where none of the
        # first is accepted (as lex3d.PlaceDatabase.query does)
        wanted = top_k + more_candidates
        futures = [self.client.submit(retrieve_task, os.path.abspath(p), q, self._stats_ref, wanted, pure=False)
                   for p, _, _ in self.shards]
        cands = []
        returned = 0
        _settle(futures)
        for i, fut in enumerate(futures):
            got = self._result(fut, i)
            returned += len(pickle.dumps(got))
            cands.extend((score, self.offsets[i] + local, i, local) for local, score in got)
        cands.sort(key=lambda c: (-c[0], c[1]))
        cands = cands[:wanted]
        t2 = time.perf_counter()
        sent = 0

        def verify_round(round_cands, second_round):
            nonlocal returned, sent
            options = {"max_distance": max_distance, "ground_vehicle": ground_vehicle, "threads": threads,
                       "second_round": second_round}
            owners = sorted({c[2] for c in round_cands})
            futures = {i: self.client.submit(verify_task, os.path.abspath(self.shards[i][0]), q,
                                             [(c[3], c[0]) for c in round_cands if c[2] == i], options, pure=False)
                       for i in owners}
            parts = []
            _settle(list(futures.values()))
            for i in owners:
                got = self._result(futures[i], i)
                returned += len(pickle.dumps(got))
                parts.append(got)
            sent += len(q) * len(owners) + 16 * len(round_cands)
            return parts, owners

        parts, owners = verify_round(cands[:top_k], False)
        matches = merge_verified(parts, [self.offsets[i] for i in owners])
        accept = parts[0]["accept_score"] if parts else 0.25
        accepted = bool(matches) and matches[0]["valid"] and matches[0]["score"] >= accept
        verifying = set(owners)
        if not accepted and len(cands) > top_k:
            parts2, owners2 = verify_round(cands[top_k:], True)
            dense = max((p["dense_candidates"] for p in parts2), default=0)
            matches = merge_round(matches, merge_verified(parts2, [self.offsets[i] for i in owners2]), dense)
            verifying |= set(owners2)
        t3 = time.perf_counter()
        if timings is not None:
            timings.update(prepare_s=t1 - t0, retrieve_s=t2 - t1, verify_s=t3 - t2, query_bytes=len(q),
                           bytes_to_workers=len(q) * len(self.shards) + sent,
                           bytes_from_workers=returned, shards_verifying=len(verifying))
        return matches[:top]

    def _result(self, fut, i):
        path = self.shards[i][0]
        try:
            r = fut.result()
        except FileNotFoundError:
            raise CompressError(2, f"{path}: shard missing (listed in {MANIFEST})") from None
        except (ValueError, OSError) as e:
            raise CompressError(2, _named(path, e)) from None
        if isinstance(r, dict) and "shard_error" in r:
            raise CompressError(2, f"{path}: shard missing (listed in {MANIFEST})" if r["missing"]
                                else _named(path, r["shard_error"]))
        return r
