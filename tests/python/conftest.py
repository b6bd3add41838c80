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
