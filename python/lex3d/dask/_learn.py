"""Distributed alphabet learning: the scans live on the workers, the BIC loop in the driver.

The likelihood of a set of scans is the sum of the scans' (ruhnke2010 eq. 4), so the gain of
a candidate word is the sum of each scan's Δ ln L. Every worker holds one shard (a contiguous
range of scans) in a Dask actor, prepared once: features, σ, neighbourhoods and the likelihood
state (lex3d._lex3d.learning.LearnScan). For each candidate the driver (LearnDecisions: the
seeded candidate order and the BIC decisions, the same C++ code lex3d.learn_alphabet runs)
sends the word to every shard, sums the per-scan changes in scan order, decides, and on
acceptance has every shard commit. The alphabet is byte for byte that of `lex3d learn` on the
same scans with the same seed.

A shard whose worker dies is rebuilt on another worker: its scans are read and prepared again
and the accepted words replayed in order, which gives the same state (learning is
deterministic), and the step that failed is repeated.
"""

import os
import pickle
import time

from ._compress import CompressError, _peak_rss_mb, job_paths, write_once
from ._progress import ProgressLine
from ._sources import ScanSources, SourceChanged, pack, unpack
from ._worker import worker_malloc


class LearnShard:
    """A Dask actor: scans [first, first + len(paths)) of the set (paths, or lex3d.Scan of a
    capture, a bag or a sequence file, read by the driver), their learning state."""

    def __init__(self, paths, first, word_radius, threads):
        worker_malloc()
        self.paths = list(unpack(paths))
        self.first = first
        self.word_radius = word_radius
        self.threads = threads
        self.scans = []
        self.cpu0 = time.process_time()

    def load(self):
        """Reads the scans: {"points": their point counts}, or {"error": the one-line message
        naming the first scan that cannot be read or is not a scan, "code": 2, as `lex3d learn`}
        (returned, not raised: an exception from an actor means a lost worker to the driver)."""
        from lex3d._lex3d import learning
        try:
            self.scans = [learning.LearnScan(p, word_radius=self.word_radius, threads=self.threads,
                                             what=p if isinstance(p, str) else p.name)
                          for p in self.paths]
        except (ValueError, OSError) as e:
            return {"error": str(e), "code": 2}
        return {"points": [s.points for s in self.scans]}

    def set_word_radius(self, index):
        return self.scans[index - self.first].set_word_radius()

    def prepare(self, radius):
        """Prepares every scan with the set's word radius: per scan (features, points, ln L,
        descriptor length)."""
        out = []
        for s in self.scans:
            s.prepare(radius)
            out.append((s.features, s.points, s.log_likelihood, s.descriptor_dim))
        return out

    def cut(self, requests, point_spacing):
        """The candidate words (bytes) of (scan, feature) pairs of this shard."""
        return [self.scans[s - self.first].cut_word(f, point_spacing) for s, f in requests]

    def evaluate(self, word, word_id):
        """Each scan's Δ ln L were `word` added as word `word_id`."""
        return [s.evaluate(word, word_id) for s in self.scans]

    def commit(self, accept):
        """Each scan's ln L after applying (or forgetting) the last evaluated word."""
        return [s.commit(accept) for s in self.scans]

    def replay(self, words):
        """Applies accepted words in order (a rebuilt shard); each scan's ln L afterwards."""
        log_ls = [s.log_likelihood for s in self.scans]
        for word_id, word in enumerate(words):
            for s in self.scans:
                s.evaluate(word, word_id)
            log_ls = [s.commit(True) for s in self.scans]
        return log_ls

    def stats(self):
        return {"pid": os.getpid(), "cpu_s": time.process_time() - self.cpu0, "peak_rss_mb": _peak_rss_mb()}


def _lost_worker_errors():
    """Exceptions that mean a shard's worker (or the connection to it) is gone."""
    import asyncio
    from distributed.comm.core import CommClosedError
    errors = [CommClosedError, OSError, asyncio.CancelledError, asyncio.TimeoutError]
    try:
        from distributed.scheduler import KilledWorker
        errors.append(KilledWorker)
    except ImportError:
        pass
    return tuple(errors)


class _Shards:
    """The driver's handles on the shards, with the bytes sent and returned, and rebuilding."""

    def __init__(self, client, sources, workers, word_radius, threads):
        self.client = client
        self.word_radius = word_radius
        self.threads = threads
        self.sources = sources
        self.feed = sources.reader()
        n = len(sources)
        k = max(1, min(len(workers), n))
        # Contiguous ranges of about equal size, one a worker.
        self.ranges = [(j * n // k, (j + 1) * n // k) for j in range(k)]
        self.owner = []
        for j, (a, b) in enumerate(self.ranges):
            self.owner.extend([j] * (b - a))
        self.workers = workers[:k]
        self.actors = [None] * k
        self.sent = 0
        self.returned = 0
        self.rebuilt = 0
        self.rebuild_pending = []  # shards whose worker died in the last all()
        self.radius = None
        self.lost = _lost_worker_errors()

    def scans(self, j):
        """Shard j's scans: paths, and the lex3d.Scan of captures', bags' and sequences' scans."""
        a, b = self.ranges[j]
        try:
            scans = self.feed.items(range(a, b))
        except SourceChanged as e:
            raise CompressError(2, str(e)) from None
        if not self.sources.multi:
            return scans
        packed = pack(scans)
        self.sent += len(packed)
        return packed

    def start(self):
        def submit(j):
            return self.client.submit(LearnShard, self.scans(j), self.ranges[j][0], self.word_radius, self.threads,
                                      actor=True, workers=[self.workers[j]], allow_other_workers=True, pure=False)
        if self.sources.multi:
            # (carried scans: one shard's at a time in the driver; an actor only keeps them)
            self.actors = [submit(j).result() for j in range(len(self.ranges))]
        else:
            futures = [submit(j) for j in range(len(self.ranges))]
            self.actors = [f.result() for f in futures]

    def _count(self, args, result):
        self.sent += len(pickle.dumps(args))
        self.returned += len(pickle.dumps(result))
        return result

    def all(self, method, *args):
        """`method` on every shard at once; the results in shard order. A shard whose worker
        died is rebuilt (see rebuild) and its call repeated."""
        futures = [getattr(a, method)(*args) for a in self.actors]
        out = []
        for j, f in enumerate(futures):
            try:
                out.append(self._count(args, f.result()))
            except self.lost:
                out.append(None)
                self.rebuild_pending.append(j)
        return out

    def one(self, j, method, *args):
        return self._count(args, getattr(self.actors[j], method)(*args).result())

    def rebuild(self, j, words):
        """A new actor for shard j on any live worker: its scans read and prepared again and
        `words` replayed in order; returns its scans' ln L."""
        f = self.client.submit(LearnShard, self.scans(j), self.ranges[j][0], self.word_radius, self.threads,
                               actor=True, pure=False)
        self.actors[j] = f.result()
        loaded = self.one(j, "load")
        if "error" in loaded:  # the scan was read before: it changed since
            raise CompressError(loaded["code"], loaded["error"])
        self.one(j, "prepare", self.radius)
        self.rebuilt += 1
        return self.one(j, "replay", list(words))


def learn(inputs, output, *, client, iterations=400, patience=100, seed=1, word_radius=0.0, threads=1,
          prefetch=64, progress=False, metadata=None, topic=None, single_return=False, sensor_model=None):
    """Learns one alphabet for every scan of `inputs` (expand_inputs) on the cluster of
    `client` and writes it to `output` (a temporary name, then renamed); returns the summary
    (a dict). The alphabet is that of `lex3d learn SCANS -o OUTPUT --iterations ITERATIONS
    --patience PATIENCE --seed SEED --word-radius WORD_RADIUS`. progress: True for a line on
stderr, or a callable given (iteration, iterations at most, BIC, words) after every
candidate. Raises CompressError when
    the job cannot run (code 1 usage, 2 a scan that cannot be read, 3 I/O). A capture, a bag
    or a sequence file counts as its scans, as `lex3d learn` counts them (read by the driver
    and sent to their shard's worker, ScanSources; metadata, topic, single_return,
    sensor_model: how they are read)."""
    from lex3d._lex3d import learning

    scans, output = job_paths(inputs, output)
    try:
        out_stat = os.stat(output)
    except OSError:
        out_stat = None
    if out_stat is not None:
        for s in scans:
            try:
                st = os.stat(s)
            except OSError:
                continue
            if (st.st_dev, st.st_ino) == (out_stat.st_dev, out_stat.st_ino):
                raise CompressError(1, f"{output}: the alphabet would overwrite the input {s}")
    try:  # the options checked once, before any work
        learning.LearnDecisions([], [], [], iterations=iterations, patience=patience, seed=seed)
        if word_radius and not 0.0 < word_radius <= 10.0:
            raise ValueError(f"word_radius must be 0 (derive) or in (0, 10] m, got {word_radius}")
        if not 1 <= threads <= 64:
            raise ValueError(f"threads must be in [1, 64], got {threads}")
    except ValueError as e:
        raise CompressError(1, str(e)) from None
    sources = ScanSources(scans, metadata=metadata, topic=topic, single_return=single_return,
                          sensor_model=sensor_model)
    n = len(sources)
    bad = sources.first_error()
    if bad is not None:  # as lex3d learn: every scan is read, or nothing is learned
        raise CompressError(2, bad)

    wall0 = time.perf_counter()
    workers = sorted(client.scheduler_info().get("workers", {}))
    if not workers:
        raise CompressError(3, "the Dask cluster has no workers")
    shards = _Shards(client, sources, workers, word_radius, threads)
    shards.start()
    loaded = shards.all("load")
    if shards.rebuild_pending:
        raise CompressError(3, "a worker died while the scans were being read")
    for part in loaded:
        if "error" in part:
            raise CompressError(part["code"], part["error"])
    points = [p for part in loaded for p in part["points"]]
    # One word radius for the set: the first scan with points (learn_word_radius).
    first = next((i for i, p in enumerate(points) if p > 0), None)
    if word_radius > 0.0:
        radius = word_radius
    elif first is None:
        radius = learning.word_radius_default()
    else:
        radius = shards.one(shards.owner[first], "set_word_radius", first)
    shards.radius = radius
    prepared = [p for part in shards.all("prepare", radius) for p in part]
    if shards.rebuild_pending:
        raise CompressError(3, "a worker died while the scans were being prepared")
    prepare_s = time.perf_counter() - wall0
    prepare_cpu = sum(st["cpu_s"] for st in shards.all("stats") if st is not None)
    spacing = learning.point_spacing(radius)
    dim = prepared[0][3] if prepared else 0

    loop = learning.LearnDecisions([p[0] for p in prepared], [p[1] for p in prepared], [p[2] for p in prepared],
                                   iterations=iterations, patience=patience, seed=seed)
    bic0 = loop.bic
    total = min(iterations, loop.candidates)
    bar = ProgressLine("learning", total, progress, lambda it, elapsed_s, bic, words: f" BIC {bic:.6g}, {words} words")
    words = []
    cache = {}
    t_learn = time.perf_counter()
    evaluations = 0

    def recover(replay_extra=()):
        """Rebuilds the shards that lost their worker; their results of a commit step."""
        pending, shards.rebuild_pending = shards.rebuild_pending, []
        return {j: shards.rebuild(j, words + list(replay_extra)) for j in pending}

    while True:
        c = loop.next()
        if c is None:
            break
        it = loop.iteration
        if it not in cache:
            # The next candidates' words, cut where their scans are (a cut does not depend
            # on the words accepted so far).
            upcoming = loop.upcoming(prefetch)
            by_shard = {}
            for k, (s, f) in enumerate(upcoming):
                by_shard.setdefault(shards.owner[s], []).append((it + k, s, f))
            for j, reqs in by_shard.items():
                while True:
                    try:
                        cut = shards.one(j, "cut", [(s, f) for _, s, f in reqs], spacing)
                        break
                    except shards.lost:
                        shards.rebuild_pending = [j]
                        recover()
                for (k, _, _), w in zip(reqs, cut):
                    cache[k] = w
        word = cache.pop(it)
        delta = 0.0
        if learning.LearnDecisions.evaluates(word):
            evaluations += 1
            parts = shards.all("evaluate", word, len(words))
            if shards.rebuild_pending:
                for j in recover():
                    parts[j] = shards.one(j, "evaluate", word, len(words))
            for part in parts:
                for d in part:
                    delta += d
        if loop.accepts(word, delta):
            parts = shards.all("commit", True)
            if shards.rebuild_pending:
                for j, lls in recover([word]).items():
                    parts[j] = lls
            log_l = 0.0
            for part in parts:
                for v in part:
                    log_l += v
            loop.accept(word, log_l)
            words.append(word)
        else:
            loop.reject()
        bar.update(loop.iteration, loop.bic, len(words))
    learn_s = time.perf_counter() - t_learn
    bar.update(loop.iteration, loop.bic, len(words), final=True)

    alphabet = learning.alphabet_file(radius, spacing, dim, words)
    job = f"learn-{os.getpid()}"
    try:
        write_once(output, alphabet, job)
    except OSError as e:
        raise CompressError(3, f"{output}: cannot write the alphabet: {e.strerror}") from None
    stats = []
    for j in range(len(shards.actors)):
        try:
            stats.append(shards.one(j, "stats"))
        except shards.lost:  # the alphabet is written; a worker lost now costs only its figures
            pass
    stats = stats or [{"cpu_s": 0.0, "peak_rss_mb": 0.0}]
    wall = time.perf_counter() - wall0
    return {
        "alphabet": output, "alphabet_bytes": len(alphabet), "scans": n, "points": sum(points),
        "notes": list(sources.notes),
        "words": len(words), "word_points": sum(int.from_bytes(w[:4], "little") for w in words), "word_radius_m": radius,
        "iterations": loop.iteration, "accepted": loop.accepted, "rejected": loop.rejected,
        "evaluations": evaluations, "bic_initial": bic0, "bic_final": loop.bic,
        "workers": len(shards.actors), "shards": [list(r) for r in shards.ranges], "rebuilt_shards": shards.rebuilt,
        "wall_s": wall, "prepare_s": prepare_s, "learn_s": learn_s,
        "candidates": loop.candidates,
        "worker_cpu_s": sum(s["cpu_s"] for s in stats),
        "worker_cpu_prepare_s": prepare_cpu,
        "worker_peak_rss_mb": max(s["peak_rss_mb"] for s in stats),
        "driver_peak_rss_mb": _peak_rss_mb(),
        "bytes_to_workers": shards.sent, "bytes_from_workers": shards.returned,
    }
