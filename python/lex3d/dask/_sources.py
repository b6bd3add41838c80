"""Where each scan of a job comes from. A file of one point cloud is read by the worker that
codes it (the task carries its path). A raw capture's turns, a ROS bag's scans and a sequence
file's models can only be read front to back: the driver reads them, in order, and each
travels to its worker as a pickled lex3d.Scan (points and every field, the sensor's laser table,
the stamp), which codes to the bytes `lex3d compress FILE` writes for that scan."""

import pickle
import warnings


def pack(obj):
    """A task's argument that carries scans (lex3d.Scan), pickled once here: its size is what
    travels, and Dask then moves bytes rather than pickling the scans again."""
    return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)


def unpack(arg):
    """On a worker: the argument pack() made, or the argument itself where it was not packed."""
    return pickle.loads(arg) if isinstance(arg, bytes) else arg


class SourceChanged(Exception):
    """A multi-scan file no longer gives the scans the survey found in it."""


class ScanSources:
    """The scans of `paths` (expand_inputs), in order: a multi-scan file (lex3d.holds_scans)
    counts as its scans, surveyed once here by reading it through (lex3d.scans with the
    options given: metadata, topic, single_return, sensor_model). A file that cannot be read,
    or whose reading fails part way, gives its scans before the failure and then one entry
    that is the error (its row in the manifest). Warnings the readers give (fields a bag's
    messages hold that lex3d does not keep) are kept in `notes`."""

    def __init__(self, paths, *, metadata=None, topic=None, single_return=False, sensor_model=None):
        import lex3d
        given = {"metadata": metadata, "topic": topic, "single_return": single_return, "sensor_model": sensor_model}
        self.read_options = {k: v for k, v in given.items() if v not in (None, False, "")}
        # (path, turn or None for a one-cloud file, name, error message or None)
        self.entries = []
        self.notes = []
        self.multi = 0
        for path in paths:
            try:
                kind = lex3d.holds_scans(path)
            except (ValueError, OSError):
                kind = ""
            if not kind:
                self.entries.append((path, None, path, None))
                continue
            self.multi += 1
            if kind == "sequence":
                # (a sequence file lists its scans: nothing to decode to count them)
                try:
                    names = lex3d.scans(path, **self.read_options).names
                except (ValueError, OSError) as e:
                    self.entries.append((path, 0, f"{path} scan 0", str(e)))
                    continue
                self.entries.extend((path, k, name, None) for k, name in enumerate(names))
                continue
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                k = 0
                try:
                    for scan in lex3d.scans(path, **self.read_options):
                        self.entries.append((path, k, scan.name, None))
                        k += 1
                except (ValueError, OSError) as e:
                    self.entries.append((path, k, f"{path} scan {k}", str(e)))
            self.notes.extend(str(w.message) for w in caught)

    def __len__(self):
        return len(self.entries)

    def name(self, i):
        return self.entries[i][2]

    def error(self, i):
        """The error entry i stands for, or None for a scan."""
        return self.entries[i][3]

    def first_error(self):
        """The first entry's error, or None when every scan was read."""
        return next((e[3] for e in self.entries if e[3] is not None), None)

    def path(self, i):
        """The path of a one-cloud file, or None for a scan of a multi-scan file."""
        path, turn, _, _ = self.entries[i]
        return path if turn is None else None

    def reader(self):
        """Reads the scans of multi-scan files as they are asked for (ScanFeed)."""
        return ScanFeed(self)


class ScanFeed:
    """The lex3d.Scan of entries of multi-scan files, asked for in increasing order within a
    file (each file is read once, front to back; asking for an earlier scan reopens it). At
    most one scan is held."""

    def __init__(self, sources):
        self.sources = sources
        self.path = None
        self.iterator = None
        self.at = 0  # the turn the iterator gives next

    def item(self, i):
        """What codes entry i: a one-cloud file's path, else its lex3d.Scan (scan)."""
        return self.sources.path(i) or self.scan(i)

    def items(self, indices):
        """item() of each of `indices`."""
        return [self.item(i) for i in indices]

    def scan(self, i):
        import lex3d
        path, turn, name, _ = self.sources.entries[i]
        if self.path != path or self.at > turn:
            self.iterator = iter(lex3d.scans(path, **self.sources.read_options))
            self.path, self.at = path, 0
        try:
            while True:
                scan = next(self.iterator)
                self.at += 1
                if self.at > turn:
                    return scan
        except StopIteration:
            raise SourceChanged(f"{name}: the file ended before this scan (it changed after it was surveyed)") from None
        except (ValueError, OSError) as e:
            raise SourceChanged(f"{name}: {e} (the file changed after it was surveyed)") from None
