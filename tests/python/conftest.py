"""Shared pytest fixtures of the lex3d Python tests."""

import pytest


@pytest.fixture(scope="module")
def client():
    """A real Dask LocalCluster for a test module: a scheduler and 2 worker processes (one
    thread each) on loopback, no dashboard port taken."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=":0")
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def compress_killing_a_worker(folder, run):
    """Runs run(client) (a lex3d.dask.compress writing k_000..., k_001... into `folder`) on a
    LocalCluster of its own with 2 workers and kills one of them with SIGKILL once k_001 is
    written (its nanny starts another). Returns (run's result, files written when the worker
    was killed)."""
    import os
    import signal
    import threading
    import time

    import distributed
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=":0")
    c = distributed.Client(cluster)
    try:
        result = {}
        job = threading.Thread(target=lambda: result.update(run(c)))
        job.start()
        deadline = time.time() + 120
        while not (folder / "k_001.lex3dm").exists() and time.time() < deadline:
            time.sleep(0.01)
        pids = c.run(os.getpid)
        os.kill(sorted(pids.values())[0], signal.SIGKILL)
        done_when_killed = len(list(folder.glob("k_*.lex3dm")))
        job.join(300)
        assert not job.is_alive()
        return result, done_when_killed
    finally:
        c.close()
        cluster.close()
