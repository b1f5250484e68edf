"""Background optimisation jobs: durable state in SQLite, resume after a restart, cancellation, events.

A job is a row in ``jobs`` (the request as JSON, its state and last progress) plus an ordered list of
``job_events`` that the API streams as server-sent events. Worker threads take queued jobs and call
``service.optimize.optimize_path`` with the shared persistent evaluation cache, so a job that was running
when the process died is simply queued again at the next start: its finished evaluations come back from
the cache and, the optimiser being deterministic for a seed, the final store equals an uninterrupted run.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from service import executors, options
from service.camera_path import CameraPath
from service.eval_cache import EvalCache
from service.evaluation import SceneHandle, read_scene
from service.lru import LRUCache
from service.octree.search import FRACTION_BEFORE_DONE
from service.optimize import Cancelled, OptimizeConfig, optimize_path
from service.params import search_space

from .storage import JobRecord, Storage

log = logging.getLogger("render_budget.jobs")


class JobCancelled(Exception):
    """Raised inside a job when its cancel flag (or the service's stop flag) is seen."""


class SceneCache:
    """Loaded ``sim_core.Scene`` objects by scene id (building a BVH is the expensive part)."""

    def __init__(self, storage: Storage, *, capacity: int = 8) -> None:
        self._storage = storage
        self._scenes: LRUCache[str, Any] = LRUCache(capacity)
        self._lock = threading.Lock()
        self._loading: dict[str, threading.Lock] = {}

    def drop(self, scene_id: str) -> None:
        """Forget a deleted scene."""
        self._scenes.pop(scene_id)

    def put(self, scene_id: str, scene: Any) -> None:
        self._scenes.put(scene_id, scene)

    def get(self, scene_id: str) -> Any:
        """The loaded scene; FileNotFoundError if its file is gone (deleted meanwhile)."""
        scene = self._scenes.get(scene_id)
        if scene is not None:
            return scene
        with self._lock:
            gate = self._loading.setdefault(scene_id, threading.Lock())
        with gate:  # one loader per scene; others wait for it
            scene = self._scenes.get(scene_id)
            if scene is None:
                # Uploads were checked self-contained; loading them the same way keeps that true.
                scene = read_scene(self._storage.scene_path(scene_id), self_contained=True)
                self._scenes.put(scene_id, scene)
            with self._lock:
                self._loading.pop(scene_id, None)
            return scene


def _plain(value: Any) -> Any:
    """JSON-friendly copy of a progress value (dataclasses, numpy scalars, tuples)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, int):
        return int(value)
    try:
        f = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f if math.isfinite(f) else None


def progress_dict(progress: Any, *, elapsed_s: float, fraction_before: float = 0.0) -> dict[str, Any]:
    """``service.optimize.Progress`` as JSON, with the elapsed time summed over all attempts of the job
    (the optimiser's own ``elapsed_s`` restarts with each attempt) and the fraction done never below
    ``fraction_before``, what an earlier attempt reached (a resumed job runs from the start again, its
    finished renders answered by the evaluation cache), unless this attempt is done."""
    out = _plain(progress)
    if not isinstance(out, dict):
        raise TypeError(f"progress must be a dataclass or a dict, got {type(progress).__name__}")
    out["elapsed_s"] = round(float(elapsed_s), 3)
    if isinstance(out.get("fraction"), float) and out["fraction"] < 1.0:
        out["fraction"] = max(out["fraction"], min(float(fraction_before), FRACTION_BEFORE_DONE))
    done, planned = int(out.get("views_done", 0)), int(out.get("views_planned", 0))
    # the views' pace stands in for an optimiser that gave no time left, while views remain: once every
    # view is done, the phases after them (the display pricing and its bridging, an hour at 1280x720)
    # have no pace by views, and "0 s left" there was wrong: the time left stays unknown there
    after_views = done == planned and isinstance(out.get("fraction"), float) and out["fraction"] < 1.0
    if out.get("estimate_s") is None and 0 < done <= planned and not after_views:
        out["estimate_s"] = round(elapsed_s * (planned - done) / done, 3)
    return out


class JobManager:
    """Queue, worker threads and bookkeeping for optimisation jobs.

    ``start()`` re-queues every job left queued or running by a previous process (that is the resume
    path); ``stop()`` asks running jobs to stop at their next check and leaves them queued in the
    database, so a clean shutdown resumes exactly like a crash.
    """

    def __init__(
        self, storage: Storage, scenes: SceneCache, *, workers: int = 2, dask_scheduler: str | None = None,
        render_threads: int | None = None, ship_scenes: bool = True, eval_workers: int = 1,
        eval_cache_max_bytes: int | None = None,
    ) -> None:
        self.storage = storage
        self.scenes = scenes
        self.workers = workers
        self.dask_scheduler = dask_scheduler
        self.render_threads = render_threads
        self.eval_workers = eval_workers
        self.ship_scenes = ship_scenes
        self.eval_cache_max_bytes = eval_cache_max_bytes
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._threads: list[threading.Thread] = []
        self._cancel: dict[str, threading.Event] = {}
        self._cancel_lock = threading.Lock()
        self._stopping = threading.Event()
        self._executor: Any = None
        self._executor_lock = threading.Lock()
        self._cache: Any = None
        self._cache_lock = threading.Lock()
        # Monotonic per-process counter the SSE endpoint watches instead of polling the database.
        self.version = 0
        self._version_cond = threading.Condition()

    # -- lifecycle ---------------------------------------------------------------------------------
    @property
    def executor_description(self) -> str:
        if self.dask_scheduler:
            return f"dask:{self.dask_scheduler}"
        return f"process-pool:{self.eval_workers}" if self.eval_workers > 1 else "in-process"

    def start(self) -> None:
        requeued = []
        for job in self.storage.list_jobs(states=("queued", "running")):
            if job.cancel_requested:
                self._finish(job.id, "cancelled", error=None)
                continue
            if job.state == "running":
                self.storage.update_job(
                    job_id=job.id, state="queued",
                    event=("resumed", {"state": "queued", "attempts": job.attempts}),
                )
            requeued.append(job.id)
            self._queue.put(job.id)
        self.storage.prune_references(keep=requeued)
        for i in range(self.workers):
            t = threading.Thread(target=self._worker, name=f"render-budget-job-{i}", daemon=True)
            t.start()
            self._threads.append(t)

    def stop(self, timeout: float = 30.0) -> None:
        """Stop at once: running jobs are interrupted (left queued, to resume at the next start) and the
        evaluation workers stopped before anything waits on them, so no process outlives the service."""
        self._stopping.set()
        with self._cancel_lock:
            for ev in self._cancel.values():
                ev.set()
        for _ in self._threads:
            self._queue.put(None)
        with self._executor_lock:
            if self._executor is not None:
                try:
                    self._executor.close()  # a job waiting on the pool sees it break and stops
                except Exception:  # closing a remote client must not block shutdown
                    log.exception("closing the executor failed")
            self._executor = None
        deadline = time.monotonic() + timeout
        for t in self._threads:
            t.join(max(0.0, deadline - time.monotonic()))
        self._threads.clear()
        with self._cache_lock:
            if self._cache is not None and hasattr(self._cache, "close"):
                self._cache.close()
            self._cache = None

    def _bump(self) -> None:
        with self._version_cond:
            self.version += 1
            self._version_cond.notify_all()

    # -- requests from the API -----------------------------------------------------------------------
    def submit(self, *, scene_id: str, spec: dict[str, Any]) -> JobRecord:
        job = self.storage.create_job(scene_id=scene_id, spec=spec)
        self._queue.put(job.id)
        self._bump()
        return job

    def delete_scene(self, *, scene_id: str) -> bool:
        """Delete a scene with its finished jobs (Conflict while it has queued or running ones)."""
        deleted = self.storage.delete_scene(scene_id=scene_id)
        self.scenes.drop(scene_id)
        if deleted:
            self._bump()
        return deleted

    def delete_job(self, *, job_id: str) -> bool:
        deleted = self.storage.delete_job(job_id=job_id)
        if deleted:
            self._bump()
        return deleted

    def cancel(self, *, job_id: str) -> JobRecord | None:
        job = self.storage.request_cancel(job_id=job_id)
        if job is not None:
            with self._cancel_lock:
                ev = self._cancel.get(job_id)
            if ev is not None:
                ev.set()
            self._bump()
        return job

    # -- shared resources ----------------------------------------------------------------------------
    def executor(self) -> Any:
        """One executor for the whole service (a Dask client is expensive to make)."""
        with self._executor_lock:
            if self._stopping.is_set():
                raise JobCancelled  # never start workers for a service that is stopping
            if self._executor is None:
                self._executor = executors.make_executor(self.dask_scheduler, self.eval_workers)
            return self._executor

    def eval_cache(self) -> Any:
        with self._cache_lock:
            if self._cache is None:
                self._cache = EvalCache(self.storage.eval_cache_path, max_bytes=self.eval_cache_max_bytes,
                                        protected=self.storage.active_scene_hashes)
            return self._cache

    # -- the worker ----------------------------------------------------------------------------------
    def _worker(self) -> None:
        while not self._stopping.is_set():
            job_id = self._queue.get()
            if job_id is None:
                return
            try:
                self._run(job_id)
            except Exception:  # keep the worker alive whatever one job does
                log.exception("job %s crashed the worker", job_id)
                self._finish(job_id, "failed", error="internal error while running the job")

    def _finish(self, job_id: str, state: str, *, error: str | None, store_id: str | None = None,
                elapsed_s: float | None = None) -> None:
        data: dict[str, Any] = {"state": state}
        if error is not None:
            data["error"] = error
        if store_id is not None:
            data["store_id"] = store_id
        self.storage.update_job(job_id=job_id, state=state, error=error, store_id=store_id,
                                finished=time.time(), elapsed_s=elapsed_s, event=(state, data))
        self.storage.drop_job_references(job_id)
        self._bump()

    def _run(self, job_id: str) -> None:
        cancel = threading.Event()
        with self._cancel_lock:  # registered before the claim, so no cancel request can slip between
            self._cancel[job_id] = cancel
        job = self.storage.claim_job(job_id=job_id)
        if job is None:  # cancelled while queued, or gone
            with self._cancel_lock:
                self._cancel.pop(job_id, None)
            return
        if job.cancel_requested:
            cancel.set()
        t0 = time.monotonic()
        base_elapsed = job.elapsed_s
        base_fraction = job.progress.get("fraction") or 0.0  # an earlier attempt's, if any
        self._bump()

        def elapsed() -> float:
            return base_elapsed + (time.monotonic() - t0)

        def should_cancel() -> bool:
            return cancel.is_set() or self._stopping.is_set()

        def on_progress(progress: Any) -> None:
            p = progress_dict(progress, elapsed_s=elapsed(), fraction_before=base_fraction)
            self.storage.update_job(job_id=job.id, progress=p, elapsed_s=elapsed(), event=("progress", p))
            self._bump()

        try:
            # Workers get the scene file (its bytes too, for Dask workers without a shared disk) and load
            # it once each; in-process the handle holds the loaded scene.
            handle = SceneHandle(self.scenes.get(job.scene_id), path=self.storage.scene_path(job.scene_id),
                                 ship_bytes=bool(self.dask_scheduler) and self.ship_scenes,
                                 self_contained=True)
            store = run_optimisation(
                job.spec, scene=handle, cache=self.eval_cache(), executor=self.executor(),
                progress=on_progress, should_cancel=should_cancel, threads=self.render_threads,
                references_dir=self.storage.job_references(job.id),
            )
            if should_cancel():
                raise JobCancelled
        except (JobCancelled, Cancelled):
            self._after_stop(job.id, elapsed())
            return
        except Exception as exc:
            if should_cancel():  # e.g. the workers were stopped under it: an interruption, not a failure
                self._after_stop(job.id, elapsed())
                return
            log.exception("job %s failed", job.id)
            self._finish(job.id, "failed", error=f"{type(exc).__name__}: {exc}", elapsed_s=elapsed())
            return
        finally:
            with self._cancel_lock:
                self._cancel.pop(job.id, None)
        body = store.to_json()
        store_id = self.storage.put_store(scene_id=job.scene_id, job_id=job.id, body=body)
        self._finish(job.id, "done", error=None, store_id=store_id, elapsed_s=elapsed())

    def _after_stop(self, job_id: str, elapsed_s: float) -> None:
        current = self.storage.get_job(job_id=job_id)
        if current is not None and current.cancel_requested:
            self._finish(job_id, "cancelled", error=None, elapsed_s=elapsed_s)
        else:  # the service is shutting down: leave it queued so the next start resumes it
            self.storage.update_job(job_id=job_id, state="queued", elapsed_s=elapsed_s,
                                    event=("interrupted", {"state": "queued"}))
            self._bump()


# -- the bridge to the optimiser (service.optimize and friends) ------------------------------------------
def build_space(spec: dict[str, Any]) -> Any:
    """The job's ParameterSpace: DESIGN.md's values (``DEFAULT_VALUES``), each parameter named in
    ``space`` given those values instead (any of ``renderable_space()``'s, kept in its order), and only
    ``parameters`` searched (others fixed at their maximum quality). Raises ValueError naming an unknown
    parameter or value."""
    try:
        space = search_space(spec.get("space"))
    except ValueError as exc:
        raise ValueError(f"space: {exc}") from None
    if spec.get("parameters"):
        space = space.subset(spec["parameters"])
    return space


#: How jobs stored by earlier versions ran the options their request did not carry.
LEGACY_SPEC_DEFAULTS = {"min_depth": 0, "view_sampling": "aimed", "path_resolution": 0.25, "guard_frames": 0}


def spec_options(spec: dict[str, Any]) -> dict[str, Any]:
    """The optimiser option values of a stored job request (``service.options`` names): requests keep
    every public option in ``options``; those stored by earlier versions kept the thresholds and the
    evaluation resolution apart and ran the options they lack as :data:`LEGACY_SPEC_DEFAULTS` says."""
    values = dict(spec.get("options") or {})
    if "thresholds" in spec or "resolution" in spec:
        thresholds = spec.get("thresholds") or {}
        legacy = {"threshold_power_w": thresholds.get("power_w"), "threshold_error": thresholds.get("error")}
        if spec.get("resolution") is not None:
            legacy["eval_width"], legacy["eval_height"] = spec["resolution"]
        values = {**LEGACY_SPEC_DEFAULTS, **{k: v for k, v in legacy.items() if v is not None}, **values}
    return options.check(values, public_only=True)


def validate_job_spec(spec: dict[str, Any]) -> None:
    """Checks that need the optimiser's definitions; raises ValueError naming the problem."""
    CameraPath.from_dict(spec["camera_path"])
    spec_options(spec)
    build_space(spec)


def run_optimisation(
    spec: dict[str, Any], *, scene: Any, cache: Any, executor: Any,
    progress: Callable[[Any], None], should_cancel: Callable[[], bool], threads: int | None = None,
    scratch_dir: Path | None = None, references_dir: Path | None = None,
) -> Any:
    """Turn a stored job request into the optimiser's inputs and run it; returns a ParetoStore.
    ``references_dir``: the job's own folder for its camera references, kept across its attempts (a
    service job); else ``scratch_dir`` holds them while it runs (a local job's folder).
    Raises ``service.optimize.Cancelled`` when ``should_cancel`` turns true."""
    path = CameraPath.from_dict(spec["camera_path"])
    config = OptimizeConfig(**spec_options(spec), profile=spec["profile"], fps=path.fps, threads=threads)
    return optimize_path(scene, path, build_space(spec), config, cache=cache, executor=executor,
                         progress=progress, should_cancel=should_cancel, scratch_dir=scratch_dir,
                         references_dir=references_dir)
