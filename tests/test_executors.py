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


class _Finished:
    """An ``on_done`` callback: records the item indices each call reports finished, and their results."""

    def __init__(self) -> None:
        self.calls: list[list[int]] = []
        self.results: dict[int, object] = {}

    def __call__(self, finished: range, results) -> None:
        self.calls.append(list(finished))
        assert len(results) == len(finished)
        self.results.update(zip(finished, results, strict=True))

    def check(self, n: int, at_least_calls: int, want: list | None = None) -> None:
        """Every item reported finished exactly once, over several calls (progress within the batch), with
        the result ``map`` returns for it (a caller can keep it before the batch ends)."""
        assert sorted(i for c in self.calls for i in c) == list(range(n))
        assert len(self.calls) >= at_least_calls
        if want is not None:
            assert [self.results[i] for i in range(n)] == want


def test_in_process_and_pool_agree() -> None:
    finished = _Finished()
    want = InProcessExecutor().map(_task, SHARED, ITEMS, on_done=finished)
    assert [w[0] for w in want] == ITEMS
    finished.check(len(ITEMS), at_least_calls=len(ITEMS), want=want)  # one call per task, in order
    assert finished.calls == [[i] for i in ITEMS]
    with ProcessPoolExecutor(2) as ex:
        assert ex.map(_task, SHARED, ITEMS) == want
        finished = _Finished()
        assert ex.map(_task, SHARED, ITEMS, on_done=finished) == want
        finished.check(len(ITEMS), at_least_calls=8, want=want)  # per chunk of tasks (4 a worker)
        calls = len(finished.calls)
        assert ex.map(_task, SHARED, [], on_done=finished) == [] and len(finished.calls) == calls
        finished = _Finished()  # one task an item (long tasks: display pricing's cameras)
        assert ex.map(_task, SHARED, ITEMS, on_done=finished, chunks=len(ITEMS)) == want
        finished.check(len(ITEMS), at_least_calls=len(ITEMS), want=want)


def _mark(folder: str, item: int) -> int:
    """A slow task that leaves a file behind, so a test can tell which tasks ran."""
    import pathlib
    import time

    time.sleep(0.02)
    (pathlib.Path(folder) / str(item)).touch()
    return item


class _Stop(Exception):
    pass


def test_a_raising_on_done_stops_the_pools_queued_tasks(tmp_path) -> None:
    """``on_done`` raising (how a job cancels a batch of cameras between them) ends ``map`` with that
    error, and the tasks still queued never run: the pool is free for the next job."""
    items = list(range(80))

    def stop(finished: range, results) -> None:
        raise _Stop

    with ProcessPoolExecutor(2) as ex:
        with pytest.raises(_Stop):
            ex.map(_mark, str(tmp_path), items, on_done=stop)
        assert ex.map(_task, SHARED, ITEMS[:3]) == InProcessExecutor().map(_task, SHARED, ITEMS[:3])
    ran = len(list(tmp_path.iterdir()))
    # 8 chunks of 10 for 2 workers: the first done, not all (the pool's own queue holds a few, which run)
    assert 10 <= ran < len(items)


def test_dask_local_cluster_agrees() -> None:
    """Threaded workers keep the test cheap; pickling to other processes is covered by the pool test."""
    from distributed import Client, LocalCluster

    want = InProcessExecutor().map(_task, SHARED, ITEMS)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cl, \
            Client(cl) as client:
        ex = DaskExecutor(client=client)
        assert ex.map(_task, SHARED, ITEMS) == want
        finished = _Finished()
        assert ex.map(_task, SHARED, ITEMS, on_done=finished) == want
        finished.check(len(ITEMS), at_least_calls=4, want=want)  # per chunk of tasks (2 a worker)
        finished = _Finished()
        assert ex.map(_task, SHARED, ITEMS, on_done=finished, chunks=len(ITEMS)) == want
        finished.check(len(ITEMS), at_least_calls=len(ITEMS), want=want)

        def stop(finished: range, results) -> None:
            raise _Stop

        with pytest.raises(_Stop):  # the rest of the batch is cancelled; the cluster serves the next one
            ex.map(_task, SHARED, ITEMS, on_done=stop)
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
