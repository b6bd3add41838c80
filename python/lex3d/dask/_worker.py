"""What every lex3d task on a Dask worker sets up first."""

import os

_MALLOC_SET = False


def worker_malloc():
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_ set, which also pins glibc's mmap
    threshold at 128 KiB: every larger buffer is then mapped and unmapped afresh. Describing the
    89 balm scans into a place database took 9.5 s of CPU so against 2.5-3.0 s without it
    (15.8 s wall against 4.4 s). The ceilings glibc's own dynamic thresholds reach (mmap 32 MiB,
    trim twice that) give the speed back; results do not depend on it. Every task and actor of
    lex3d.dask calls it first."""
    global _MALLOC_SET
    if _MALLOC_SET or "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    _MALLOC_SET = True
    try:
        import ctypes
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD
        libc.mallopt(-1, 64 << 20)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass  # not glibc: nothing pinned it
