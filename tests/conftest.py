"""Shared fixtures: a local Dask cluster configured as the study runner configures its own."""

import contextlib

import pytest


@contextlib.contextmanager
def local_client(memory_limit: str):
    import dask
    from distributed import Client, LocalCluster

    from cvxdual.study.runner import local_config
    with dask.config.set(local_config()):
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, memory_limit=memory_limit,
                               dashboard_address=":0", silence_logs=50)
    cl = Client(cluster)
    try:
        yield cl
    finally:
        cl.close()
        cluster.close()


@pytest.fixture(scope="module")
def client(request):
    """A two-worker local cluster; a module sets ``CLUSTER_MEMORY`` to change the per-worker limit."""
    with local_client(getattr(request.module, "CLUSTER_MEMORY", "2GB")) as cl:
        yield cl
