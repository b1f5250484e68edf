"""Executors: where batches of evaluations run (in-process, a local process pool, a Dask cluster).

All three run ``fn(shared, item)`` for every item of a batch and return the results in order, so the
optimiser's results do not depend on the executor. ``shared`` (e.g. the scene reference and the
evaluation settings) travels once per worker and batch rather than once per item: in chunks for the
process pool, scattered and broadcast for Dask. ``fn`` must be a module-level (picklable) function.

Dask: start ``dask scheduler`` on one machine and ``dask worker tcp://HOST:8786`` on each render node
(or dask-jobqueue on a farm), then pass the scheduler address; workers need this package installed.
"""

from __future__ import annotations

import concurrent.futures as cf
import ctypes
import itertools
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol, TypeVar

T = TypeVar("T")
R = TypeVar("R")


#: ``on_done(finished, results)``: called in the caller's thread with the indices (into ``items``) of the
#: tasks that just finished and their results, per task or per chunk of tasks, so that a long batch can
#: report progress, and keep what it has, before it ends (``on_done`` raising stops the batch).
OnDone = Callable[[range, Sequence[Any]], None]


class Executor(Protocol):
    """Runs a batch of independent tasks; results come back in input order."""

    name: str

    def map(self, fn: Callable[[Any, Any], R], shared: Any, items: Sequence[Any],
            on_done: OnDone | None = None, *, chunks: int | None = None) -> list[R]:
        """``fn(shared, item)`` for every item. ``chunks``: how many tasks a pool or cluster splits the
        items into (default a few per worker, for short tasks; ``len(items)`` for tasks of minutes, so
        that each reports as it ends and a worker that is free takes the next)."""
        ...

    def close(self) -> None: ...


def _run_chunk(fn: Callable[[Any, Any], R], shared: Any, chunk: Sequence[Any]) -> list[R]:
    return [fn(shared, x) for x in chunk]


def _chunks(items: Sequence[T], n: int) -> list[Sequence[T]]:
    n = max(1, min(n, len(items)))
    size = -(-len(items) // n)
    return [items[i:i + size] for i in range(0, len(items), size)]


def _spans(chunks: Sequence[Sequence[Any]]) -> list[range]:
    """The item indices each of ``chunks`` (consecutive slices of the items) holds."""
    starts = [0, *itertools.accumulate(len(c) for c in chunks)]
    return [range(a, b) for a, b in itertools.pairwise(starts)]


class InProcessExecutor:
    """Runs tasks in the calling thread (the default; the tracer itself is multithreaded)."""

    name = "in-process"

    def map(self, fn: Callable[[Any, Any], R], shared: Any, items: Sequence[Any],
            on_done: OnDone | None = None, *, chunks: int | None = None) -> list[R]:
        out: list[R] = []
        for i, x in enumerate(items):
            out.append(fn(shared, x))
            if on_done is not None:
                on_done(range(i, i + 1), out[-1:])
        return out

    def close(self) -> None:
        pass

    def __enter__(self) -> InProcessExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
PARENT_POLL_S = 0.25


def die_with_parent(parent_pid: int) -> None:
    """Pool-worker initializer: the worker ends when the process that started it ends, however that
    ended (a SIGKILLed service must not leave workers rendering its queue). Linux delivers SIGKILL at
    once (PR_SET_PDEATHSIG; the "parent" is the thread that started the worker, so the pool is made and
    fed by threads that outlive it); everywhere a daemon thread also watches the parent's pid."""
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass  # no prctl (an unusual libc): the watch thread still works
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)
    threading.Thread(target=_exit_when_orphaned, args=(parent_pid,), name="render-budget-parent-watch",
                     daemon=True).start()


def _exit_when_orphaned(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


class ProcessPoolExecutor:
    """A pool of local worker processes (spawned: safe with threads and native state). Workers die with
    this process (:func:`die_with_parent`) and are stopped, not waited for, by :meth:`close`."""

    name = "process-pool"

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or max(1, (os.cpu_count() or 1))
        if self.workers < 1:
            raise ValueError("workers must be >= 1")
        self._pool = cf.ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"),
                                            initializer=die_with_parent, initargs=(os.getpid(),))

    def map(self, fn: Callable[[Any, Any], R], shared: Any, items: Sequence[Any],
            on_done: OnDone | None = None, *, chunks: int | None = None) -> list[R]:
        if not items:
            return []
        parts = _chunks(items, chunks or 4 * self.workers)
        futures = [self._pool.submit(_run_chunk, fn, shared, c) for c in parts]
        try:
            if on_done is not None:
                spans = dict(zip(futures, _spans(parts), strict=True))
                for f in cf.as_completed(futures):
                    on_done(spans[f], f.result())  # a failed task raises here, before later progress
            out: list[R] = []
            for f in futures:
                out.extend(f.result())
            return out
        except BaseException:  # (a failed task, or on_done raising to cancel): the queued tasks never start
            for f in futures:
                f.cancel()
            raise

    def close(self, timeout_s: float = 5.0) -> None:
        """Cancel queued tasks and stop the workers now (SIGTERM, then SIGKILL after ``timeout_s``): a
        stopping service must not leave them rendering. A ``map`` still waiting raises BrokenProcessPool."""
        # The standard pool has no public way to stop busy workers before Python 3.14: take its list.
        processes = list((getattr(self._pool, "_processes", None) or {}).values())
        self._pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            if p.is_alive():
                p.terminate()
        deadline = time.monotonic() + timeout_s
        for p in processes:
            p.join(max(0.0, deadline - time.monotonic()))
            if p.is_alive():
                p.kill()
                p.join(timeout_s)
        self._pool.shutdown(wait=True)  # reaps the pool's management thread

    def __enter__(self) -> ProcessPoolExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class DaskExecutor:
    """Tasks on a Dask distributed cluster, given a scheduler address or an existing ``Client``."""

    name = "dask"

    def __init__(self, address: str | None = None, client: Any = None, timeout_s: float = 30.0) -> None:
        from distributed import Client  # lazy: dask is heavy and only this executor needs it

        if (address is None) == (client is None):
            raise ValueError("give a scheduler address or a client")
        self._own = client is None
        self.client = Client(address, timeout=timeout_s) if client is None else client
        self.address = address or getattr(client.scheduler, "address", "client")

    def _n_workers(self) -> int:
        try:
            return max(1, len(self.client.scheduler_info(n_workers=-1).get("workers", {})))
        except TypeError:  # older signature
            return max(1, len(self.client.scheduler_info().get("workers", {})))

    def map(self, fn: Callable[[Any, Any], R], shared: Any, items: Sequence[Any],
            on_done: OnDone | None = None, *, chunks: int | None = None) -> list[R]:
        if not items:
            return []
        # Scatter the payload as ONE object: scattering a dict would scatter its values under their own
        # keys ("weights", ...), which collide across calls and clients and get released under us.
        [shared_f] = self.client.scatter([shared], broadcast=True, hash=False)
        parts = _chunks(items, chunks or 2 * self._n_workers())
        futures = [self.client.submit(_run_chunk, fn, shared_f, c, pure=False) for c in parts]
        try:
            if on_done is not None:
                from distributed import as_completed  # lazy, as in __init__: only this executor needs dask

                spans = {f.key: span for f, span in zip(futures, _spans(parts), strict=True)}
                got: dict[Any, list[R]] = {}
                for f, part in as_completed(futures, with_results=True):  # each part fetched once
                    got[f.key] = part
                    on_done(spans[f.key], part)
                return [r for f in futures for r in got[f.key]]
            out: list[R] = []
            for part in self.client.gather(futures):
                out.extend(part)
            return out
        except BaseException:
            self.client.cancel(futures)
            raise

    def close(self) -> None:
        if self._own:
            self.client.close()

    def __enter__(self) -> DaskExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def make_executor(dask_scheduler: str | None = None, workers: int | None = None) -> Executor:
    """Dask when a scheduler address is given, a process pool for ``workers > 1``, else in-process."""
    if dask_scheduler:
        return DaskExecutor(dask_scheduler)
    if workers and workers > 1:
        return ProcessPoolExecutor(workers)
    return InProcessExecutor()
