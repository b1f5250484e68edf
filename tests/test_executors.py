"""Executors give identical, ordered results: in-process, process pool, and a real Dask LocalCluster."""

from __future__ import annotations

import numpy as np
import pytest

from service.executors import DaskExecutor, InProcessExecutor, ProcessPoolExecutor, make_executor


def _task(shared: dict, item: int) -> tuple[int, float]:
    """Deterministic numeric work depending on the shared payload and the item."""
    rng = np.random.default_rng(item)
    return item, float(np.sum(shared["weights"] * rng.random(shared["weights"].size)))


SHARED = {"weights": np.linspace(0.0, 1.0, 257)}
ITEMS = list(range(37))


def test_in_process_and_pool_agree() -> None:
    want = InProcessExecutor().map(_task, SHARED, ITEMS)
    assert [w[0] for w in want] == ITEMS
    with ProcessPoolExecutor(2) as ex:
        assert ex.map(_task, SHARED, ITEMS) == want
        assert ex.map(_task, SHARED, []) == []


def test_dask_local_cluster_agrees() -> None:
    """Threaded workers keep the test cheap; pickling to other processes is covered by the pool test."""
    from distributed import Client, LocalCluster

    want = InProcessExecutor().map(_task, SHARED, ITEMS)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cl, \
            Client(cl) as client:
        ex = DaskExecutor(client=client)
        assert ex.map(_task, SHARED, ITEMS) == want
        ex.close()  # does not close a client it did not open
        assert client.status == "running"
        by_address = DaskExecutor(cl.scheduler_address)
        assert by_address.map(_task, SHARED, ITEMS[:5]) == want[:5]
        by_address.close()


def test_make_executor() -> None:
    assert make_executor().name == "in-process"
    ex = make_executor(workers=2)
    assert ex.name == "process-pool"
    ex.close()
    with pytest.raises(ValueError):
        DaskExecutor()
