"""Distributed compression: the driver (compress) and the work a worker does for one scan."""

import hashlib
import itertools
import json
import os
import pickle
import resource
import time
import uuid
import warnings

from ._files import read_alphabet_file
from ._progress import ProgressLine
from ._sources import ScanSources, SourceChanged, pack, unpack
from ._worker import worker_malloc

# Point cloud files a folder is searched for (pose lists, READMEs and times.txt are not scans).
SCAN_EXTENSIONS = (".bin", ".pcd", ".ply", ".las", ".xyz", ".3d", ".pcap", ".bag", ".lex3dq")

# Scans of a capture, bag or sequence file a task carries at most (each ~1-4 MB pickled).
SCANS_CARRIED = 4


class CompressError(Exception):
    """A job that cannot start (bad arguments, inputs or outputs): `code` is the exit code
    (1 usage, 2 bad data, 3 I/O) and the message one line naming what is wrong."""

    def __init__(self, code, message):
        super().__init__(message)
        self.code = code


def expand_inputs(items):
    """The scans of `items`, in order: a file is itself, a folder its point cloud files sorted
    by name, `@LIST` the paths in LIST (one a line, relative to LIST's folder; # comments)."""
    scans = []
    for item in items:
        item = os.fspath(item)
        if item.startswith("@"):
            listing = item[1:]
            try:
                with open(listing, encoding="utf-8") as f:
                    lines = f.read().splitlines()
            except OSError as e:
                raise CompressError(3, f"{listing}: cannot read the file list: {e.strerror}") from None
            base = os.path.dirname(listing)
            for line in lines:
                line = line.strip()
                if line and not line.startswith("#"):
                    scans.append(os.path.join(base, line))
        elif os.path.isdir(item):
            found = sorted(e.path for e in os.scandir(item)
                           if e.is_file() and os.path.splitext(e.name)[1].lower() in SCAN_EXTENSIONS)
            if not found:
                raise CompressError(2, f"{item}: a folder with no point cloud files ({', '.join(SCAN_EXTENSIONS)})")
            scans.extend(found)
        else:
            scans.append(item)
    if not scans:
        raise CompressError(1, "no scans given")
    return scans


def job_paths(inputs, output):
    """The scans of `inputs` (expand_inputs) and `output` as a path; CompressError (3) when
    the output's folder does not exist."""
    scans = expand_inputs(inputs)
    output = os.fspath(output)
    out_dir = os.path.dirname(output) or "."
    if not os.path.isdir(out_dir):
        raise CompressError(3, f"{output}: the folder {out_dir} does not exist")
    return scans, output


def numbered_output(output, index, count):
    """OUT for one scan; OUT's stem + "_<index>" (3 digits at least) + extension for several,
    as `lex3d compress` names its files."""
    if count <= 1:
        return output
    head, tail = os.path.split(output)
    stem, ext = os.path.splitext(tail)
    return os.path.join(head, f"{stem}_{index:03d}{ext}")


def _sha256(data):
    return hashlib.sha256(data).hexdigest()


def _temporary_name(path, job):
    head, tail = os.path.split(path)
    return os.path.join(head, f".{tail}.lex3d-dask-{job}-{os.getpid()}.tmp")


def write_once(path, data, job):
    """Writes `data` to `path` through a temporary file in the same folder and a rename, so
    `path` is never partial. A file already there with the same bytes (a retried scan) is
    left alone: returns False then, True when written."""
    try:
        with open(path, "rb") as f:
            if f.read() == data:
                return False
    except OSError:
        pass
    tmp = _temporary_name(path, job)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return True


def learn_task(paths, iterations, seed_kw, threads):
    """On a worker: the alphabet file (bytes) learned on `paths`, as `lex3d learn`."""
    import lex3d
    worker_malloc()
    return lex3d.learn_alphabet(list(paths), iterations=iterations, threads=threads, **seed_kw)


def code_batch(items, alphabet, options, job):
    """On a worker: codes the scans of `items` ((index, path or lex3d.Scan, output) each, or
    those pickled), one after the other, and returns their manifest rows (code_task)."""
    worker_malloc()
    return [code_task(index, path, output, alphabet, options, job) for index, path, output in unpack(items)]


def batch_size(remaining, slots, largest=16):
    """Scans in the next task: guided scheduling. A task costs the driver and the in-process
    scheduler ~6 ms of CPU whatever it holds (measured on 2 LocalCluster workers: 0.77 s of
    driver CPU for 89 one-scan tasks of ~85 ms), which on a small machine competes with the
    workers; large tasks while much work is left, down to one scan at the end so that no
    worker waits long for the last one. A dead worker's task is retried whole."""
    return max(1, min(largest, remaining // (4 * max(1, slots))))


def code_task(index, path, output, alphabet, options, job):
    """On a worker: codes one scan (a path, or a lex3d.Scan read by the driver) into `output`
    and returns its manifest row. A scan that cannot be read or coded gives a row with status
    "error" and the one-line message."""
    import lex3d
    worker_malloc()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    row = {"index": index, "scan": path if isinstance(path, str) else path.name, "file": output}
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            data, info = lex3d.compress(path, alphabet=alphabet, report=True, **options)
        row["notes"] = [str(w.message) for w in caught]
        written = write_once(output, data, job)
    except (ValueError, OSError) as e:
        row.update(status="error", error=str(e))
    else:
        row.update(status="ok", bytes=info["bytes"], points=info["points"],
                   bits_per_point=info["bits_per_point"], max_error=info["max_error"],
                   words=info["words"], attributes=info["attributes"],
                   dropped_attributes=info["dropped_attributes"], sha256=_sha256(data), written=written)
    row["cpu_s"] = time.process_time() - cpu0
    row["wall_s"] = time.perf_counter() - wall0
    row["worker_peak_rss_mb"] = _peak_rss_mb()
    row["pid"] = os.getpid()
    return row


def _peak_rss_mb():
    """This process's peak resident memory: VmHWM (of this process image; getrusage's
    ru_maxrss also counts what the parent held when it forked the worker)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _uses_words(options):
    words = options.get("words")
    if words is not None:
        return words != "off"
    return options.get("max_error") is None and options.get("target_bpp") is None


def compress(inputs, output, *, client, alphabet=None, save_alphabet=None, learn_scans=5,
             iterations=400, seed=None, manifest=None, progress=False, window=None, batch=None,
             metadata=None, topic=None, single_return=False, sensor_model=None, **options):
    """Codes every scan of `inputs` (expand_inputs) on the cluster of `client` into OUT_000,
    OUT_001, ... (numbered_output) and writes the manifest; returns the summary (a dict).

    alphabet: an alphabet file (path or bytes) to reuse; otherwise, when words are used, one is
    learned on `learn_scans` evenly spaced scans on one worker and written to `save_alphabet`
    (default: OUT's stem + ".lex3da"). options: those of lex3d.compress (max_error, target_bpp,
    words, layer_coding, keep_all_points, fast, objective, word_radius, threads). A scan that fails is named in
    the manifest and the summary; the others complete. Raises CompressError when the job
    cannot start. window: tasks in flight (default 4 a worker thread); batch: scans a task
    (default: batch_size, from 16 down to 1 as the work runs out; at most SCANS_CARRIED of a
    capture's, a bag's or a sequence file's scans, which travel with their task).

    A raw capture, a ROS bag or a sequence file (.lex3dq) counts as its scans, as `lex3d
    compress` counts them: the driver reads it through once to count them, then again as the
    tasks go out, each scan travelling to its worker pickled (ScanSources). metadata, topic,
    single_return, sensor_model: how those files are read (lex3d.scans)."""
    import lex3d
    from distributed import as_completed

    paths, output = job_paths(inputs, output)
    survey0 = time.perf_counter()
    sources = ScanSources(paths, metadata=metadata, topic=topic, single_return=single_return,
                          sensor_model=sensor_model)
    n = len(sources)
    survey_s = time.perf_counter() - survey0
    stem = os.path.splitext(output)[0]
    manifest = os.fspath(manifest) if manifest else stem + ".manifest.jsonl"
    words = _uses_words(options)
    if alphabet is not None and not words:
        raise CompressError(1, "words off uses no alphabet: drop --alphabet (or give --words on)")
    alphabet_path = None
    if isinstance(alphabet, (bytes, bytearray)):
        alphabet_bytes = bytes(alphabet)
    elif alphabet is not None:
        alphabet_path = os.fspath(alphabet)
        alphabet_bytes = read_alphabet_file(alphabet_path)
    else:
        alphabet_bytes = None
    if words and alphabet_bytes is None:
        alphabet_path = os.fspath(save_alphabet) if save_alphabet else stem + ".lex3da"
    # Every output checked against every input (by file identity) before any work: nothing
    # is overwritten. One stat a file; the identities are held only for this check.
    inputs_seen = {}
    for src in paths + ([alphabet_path] if alphabet_bytes is not None and alphabet_path else []):
        try:
            st = os.stat(src)
            inputs_seen[(st.st_dev, st.st_ino)] = src
        except OSError:
            pass  # a missing scan is that scan's error, reported in the manifest
    extra = [manifest] + ([alphabet_path] if alphabet_bytes is None and words else [])
    extra_abs = {os.path.abspath(p) for p in extra}
    if len(extra_abs) != len(extra):
        raise CompressError(1, f"{manifest}: the manifest and the alphabet would share a name")
    for i, out in enumerate(itertools.chain((numbered_output(output, i, n) for i in range(n)), extra)):
        if i < n and os.path.abspath(out) in extra_abs:
            raise CompressError(1, f"{out}: a scan's output and the manifest or alphabet share a name")
        try:
            st = os.stat(out)
        except OSError:
            continue
        if (st.st_dev, st.st_ino) in inputs_seen:
            raise CompressError(1, f"{out}: an output would overwrite the input {inputs_seen[(st.st_dev, st.st_ino)]}")
    del inputs_seen

    # The options, and an alphabet given, checked once here rather than failing every scan:
    # an empty scan codes in well under a millisecond.
    import numpy as np
    empty = np.zeros((0, 3), np.float32)
    try:
        lex3d.compress(empty, **options)
    except ValueError as e:
        raise CompressError(1, str(e)) from None
    if alphabet_bytes is not None:
        try:
            lex3d.compress(empty, alphabet=alphabet_bytes, **options)
        except ValueError as e:
            raise CompressError(2, f"{alphabet_path or 'alphabet'}: {e}") from None

    job = uuid.uuid4().hex[:12]
    seed_kw = {} if seed is None else {"seed": seed}
    wall0 = time.perf_counter()
    learn_s = 0.0
    if words and alphabet_bytes is None:
        k = min(n, max(1, learn_scans))
        feed = sources.reader()
        try:
            sample = feed.items(i for i in (j * n // k for j in range(k)) if sources.error(i) is None)
        except SourceChanged as e:
            raise CompressError(2, f"learning the alphabet: {e}") from None
        if not sample:
            raise CompressError(2, f"learning the alphabet: no scan could be read ({sources.error(0)})")
        del feed
        t = time.perf_counter()
        fut = client.submit(learn_task, sample, iterations, seed_kw, options.get("threads", 1), pure=False)
        del sample
        try:
            alphabet_bytes = fut.result()
        except (ValueError, OSError) as e:
            raise CompressError(2, f"learning the alphabet: {e}") from None
        learn_s = time.perf_counter() - t
        write_once(alphabet_path, alphabet_bytes, job)
    coding = dict(options)
    coding.setdefault("threads", 1)
    if words:
        coding.setdefault("iterations", iterations)
        coding.update(seed_kw)
    # The alphabet goes to every worker once, under its content hash; tasks refer to it.
    alphabet_sha = _sha256(alphabet_bytes) if alphabet_bytes is not None else None
    alphabet_ref = None
    if alphabet_bytes is not None:
        alphabet_ref = client.scatter({f"lex3d-alphabet-{alphabet_sha[:16]}": alphabet_bytes},
                                      broadcast=True)[f"lex3d-alphabet-{alphabet_sha[:16]}"]
    workers = len(client.scheduler_info().get("workers", {}))
    slots = max(1, sum(client.nthreads().values()))
    window = window or 4 * slots

    header = {"lex3d": lex3d.__version__, "scans": n, "alphabet": alphabet_path,
              "alphabet_sha256": alphabet_sha, "options": {k: v for k, v in coding.items()}}
    if sources.read_options:
        header["read_options"] = dict(sources.read_options)
    if sources.notes:
        header["notes"] = list(sources.notes)
    tmp_manifest = _temporary_name(manifest, job)
    bar = ProgressLine("coding", n, progress, lambda done, elapsed_s, failed:
                       f" {done / max(1e-9, elapsed_s):.1f} scans/s" + (f", {failed} failed" if failed else ""))
    done = failed = 0
    next_row = 0
    pending = {}
    totals = {"bytes": 0, "points": 0, "cpu_s": 0.0, "task_bytes": 0, "result_bytes": 0,
              "peak_rss_mb": 0.0, "rewritten": 0}
    failures = []
    cpu_per_scan = []
    # Carried scans stay in their task rather than scattered to a worker ahead of it: a task
    # retried after its worker died finds them there. Dask's warning about large tasks (given
    # from its own thread, after submit returns) is expected of them while the job runs.
    if sources.multi:
        warnings.filterwarnings("ignore", "Large object of size .* detected in task graph", UserWarning)
    quiet = warnings.filters[0] if sources.multi else None
    try:
        with open(tmp_manifest, "w", encoding="utf-8") as mf:
            mf.write(json.dumps(header) + "\n")
            queue = as_completed()
            submitted = 0

            feed = sources.reader()

            def submit(first, count):
                """Sends scans first..first+count-1 to a task; False when none of them needs
                one. A scan of a multi-scan file travels with its task; an entry that is an
                error, or a scan the file no longer gives, is its row now."""
                items = []
                for i in range(first, first + count):
                    out = numbered_output(output, i, n)
                    error = sources.error(i)
                    if error is None:
                        try:
                            items.append((i, feed.item(i), out))
                        except SourceChanged as e:
                            error = str(e)
                    if error is not None:
                        record({"index": i, "scan": sources.name(i), "file": out, "status": "error",
                                "error": error, "cpu_s": 0.0, "wall_s": 0.0, "worker_peak_rss_mb": 0.0})
                if not items:
                    return False
                # (carried scans pickled here once: the task's size is counted from them, and
                # Dask then moves bytes)
                if any(not isinstance(it[1], str) for it in items):
                    items = pack(items)
                    totals["task_bytes"] += len(items) + len(pickle.dumps((b"", coding, job)))
                else:
                    totals["task_bytes"] += len(pickle.dumps((items, coding, job)))
                queue.add(client.submit(code_batch, items, alphabet_ref, coding, job,
                                        key=f"lex3d-code-{job}-{first}-{count}", retries=2))
                return True

            # At most `window` tasks in flight, the rows written in scan order as they
            # complete; rows that wait for an earlier, slower scan are held, at most
            # `reorder` of them (a slow scan stops new work only after that many): the driver's
            # memory is bounded whatever the number of scans.
            reorder = max(16 * window, 4096)
            in_flight = 0

            def top_up():
                nonlocal submitted, in_flight
                while submitted < n and in_flight < window and submitted - next_row < reorder:
                    count = min(n - submitted, batch or batch_size(n - submitted, slots))
                    # (a task holds one-cloud files or carried scans, at most SCANS_CARRIED of those)
                    carried = sources.path(submitted) is None
                    run = 1
                    while run < count and (sources.path(submitted + run) is None) == carried:
                        run += 1
                    count = min(run, SCANS_CARRIED) if carried else run
                    if submit(submitted, count):
                        in_flight += 1
                    submitted += count
                    flush()

            def flush():
                """Writes the rows that are next in scan order."""
                nonlocal next_row
                while next_row in pending:
                    mf.write(json.dumps(pending.pop(next_row)) + "\n")
                    next_row += 1

            def record(row):
                nonlocal done, failed
                pending[row["index"]] = row
                done += 1
                if row["status"] == "ok":
                    totals["bytes"] += row["bytes"]
                    totals["points"] += row["points"]
                    totals["rewritten"] += 0 if row["written"] else 1
                else:
                    failed += 1
                    if len(failures) < 20:
                        # (lex3d's messages already start with the file they name)
                        named = row["error"].startswith(row["scan"] + ":")
                        failures.append(row["error"] if named else f"{row['scan']}: {row['error']}")
                totals["cpu_s"] += row["cpu_s"]
                if "pid" in row and len(cpu_per_scan) < 100000:  # (of the coded scans; the first 1e5)
                    cpu_per_scan.append(row["cpu_s"])
                totals["peak_rss_mb"] = max(totals["peak_rss_mb"], row["worker_peak_rss_mb"])

            top_up()
            for fut in queue:
                in_flight -= 1
                rows = fut.result()
                fut.release()
                totals["result_bytes"] += len(pickle.dumps(rows))
                for row in rows:
                    record(row)
                flush()
                top_up()
                bar.update(done, failed)
            mf.flush()
            os.fsync(mf.fileno())
        os.replace(tmp_manifest, manifest)
    finally:
        if quiet is not None and quiet in warnings.filters:
            warnings.filters.remove(quiet)
            getattr(warnings, "_filters_mutated", lambda: None)()
        if done:
            bar.update(done, failed, final=True)
        _remove_temporaries(os.path.dirname(output) or ".", job)
        if os.path.exists(tmp_manifest):
            os.unlink(tmp_manifest)
    wall = time.perf_counter() - wall0
    cpu_per_scan.sort()
    return {
        "scans": n, "ok": n - failed, "failed": failed, "failures": failures, "notes": list(sources.notes),
        "manifest": manifest, "alphabet": alphabet_path, "alphabet_sha256": alphabet_sha,
        "alphabet_bytes": len(alphabet_bytes) if alphabet_bytes is not None else 0,
        "workers": workers, "threads": slots, "wall_s": wall, "learn_s": learn_s, "survey_s": survey_s,
        "scans_per_s": n / wall if wall > 0 else 0.0,
        "points": totals["points"], "bytes": totals["bytes"],
        "bits_per_point": 8.0 * totals["bytes"] / totals["points"] if totals["points"] else 0.0,
        "cpu_s": totals["cpu_s"],
        "cpu_s_median": cpu_per_scan[len(cpu_per_scan) // 2] if cpu_per_scan else 0.0,
        "worker_peak_rss_mb": totals["peak_rss_mb"],
        "bytes_to_workers": totals["task_bytes"] + workers * (len(alphabet_bytes) if alphabet_bytes else 0),
        "bytes_from_workers": totals["result_bytes"],
        "already_written": totals["rewritten"],
    }


def _remove_temporaries(folder, job):
    """Temporary files of this job a dead worker may have left behind."""
    marker = f".lex3d-dask-{job}-"
    try:
        for e in os.scandir(folder):
            if marker in e.name and e.name.endswith(".tmp"):
                try:
                    os.unlink(e.path)
                except OSError:
                    pass
    except OSError:
        pass
