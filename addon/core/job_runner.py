"""Submit an optimisation job and follow it to the finished store (pure: HTTP through the client only).

Used by the operator's worker thread (GUI), by its synchronous execute() (background/batch) and by tests.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .client import ServiceClient, ServiceError

TERMINAL = ("done", "failed", "cancelled")


class JobFailed(RuntimeError):
    """The service reported the job as failed (message from the service)."""


class JobCancelled(RuntimeError):
    """The job was cancelled (by us or on the service)."""


@dataclass(frozen=True)
class JobOptions:
    """Everything a job needs besides the scene and the path (mirrors the service's JobCreate)."""

    profile: str = "mobile"
    parameters: tuple[str, ...] | None = None  # None: all, minus inert (service default)
    threshold_power_w: float = 0.05
    threshold_error: float = 0.01
    max_depth: int = 6
    view_sampling: str = "path"  # "path" | "aimed" | "axis" (service.optimize.OptimizeOptions)
    path_resolution: float = 0.25
    guard_frames: int = 2
    population: int = 24
    generations: int = 25
    seed: int = 0
    exhaustive_limit: int = 512
    resolution: tuple[int, int] = (64, 48)

    def __post_init__(self) -> None:
        for name in ("threshold_power_w", "threshold_error"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v}")
        if self.threshold_error > 1:
            raise ValueError(f"threshold_error must be <= 1, got {self.threshold_error}")
        if not 0 <= self.max_depth <= 8:
            raise ValueError(f"max_depth must be in 0..8, got {self.max_depth}")
        if self.view_sampling not in ("path", "aimed", "axis"):
            raise ValueError(f"view_sampling must be path, aimed or axis, got {self.view_sampling!r}")
        if not (math.isfinite(self.path_resolution) and 0 < self.path_resolution <= 10):
            raise ValueError(f"path_resolution must be in (0, 10], got {self.path_resolution}")
        if not 0 <= self.guard_frames <= 8:
            raise ValueError(f"guard_frames must be in 0..8, got {self.guard_frames}")
        w, h = self.resolution
        if not (4 <= w <= 1024 and 4 <= h <= 1024):
            raise ValueError(f"evaluation resolution must be within 4..1024 pixels, got {w}x{h}")
        if self.parameters is not None and not self.parameters:
            raise ValueError("select at least one parameter to search")

    def payload(self, scene_id: str, path_doc: dict[str, Any]) -> dict[str, Any]:
        body: dict[str, Any] = {
            "scene_id": scene_id,
            "camera_path": path_doc,
            "thresholds": {"power_w": self.threshold_power_w, "error": self.threshold_error},
            "options": {"max_depth": self.max_depth, "view_sampling": self.view_sampling,
                        "path_resolution": self.path_resolution, "guard_frames": self.guard_frames,
                        "population": self.population, "generations": self.generations, "seed": self.seed,
                        "exhaustive_limit": self.exhaustive_limit},
            "profile": self.profile,
            "resolution": [int(self.resolution[0]), int(self.resolution[1])],
        }
        if self.parameters is not None:
            body["parameters"] = list(self.parameters)
        return body


@dataclass(frozen=True)
class JobUpdate:
    """A progress report for the UI / text progress bar."""

    state: str
    fraction: float
    text: str


@dataclass
class JobOutcome:
    job_id: str
    scene_id: str
    store_id: str
    store_text: str
    scene_info: dict[str, Any] = field(default_factory=dict)
    job: dict[str, Any] = field(default_factory=dict)


def describe(job: dict[str, Any], evals_per_view: int | None = None) -> JobUpdate:
    """Fraction done and a one-line status from a GET /jobs/{id} body.

    The optimiser finishes the views of an octree level together, so `views_done` moves in jumps; with
    `evals_per_view` (population x generations) the fraction also follows the renders inside a level.
    """
    p = job.get("progress") or {}
    done, planned = int(p.get("views_done") or 0), int(p.get("views_planned") or 0)
    evals = int(p.get("evaluations") or 0) + int(p.get("cache_hits") or 0)
    state = str(job.get("state", "?"))
    frac = min(1.0, done / planned) if planned > 0 else 0.0
    if evals_per_view and planned > 0:
        frac = max(frac, min(0.99, evals / (planned * evals_per_view)))
    if state == "done":
        frac = 1.0
    phase = f" [{p['phase']}]" if isinstance(p.get("phase"), str) and state == "running" else ""
    text = f"{state}{phase}: {done}/{planned} views, {int(p.get('evaluations') or 0)} evaluations"
    if p.get("cache_hits"):
        text += f" ({int(p['cache_hits'])} cached)"
    if p.get("estimate_s") is not None and state == "running":
        text += f", ~{float(p['estimate_s']):.0f} s left"
    if job.get("error"):
        text += f" - {job['error']}"
    return JobUpdate(state, frac, text)


def run_job(client: ServiceClient, glb_path: str | Path, path_doc: dict[str, Any], options: JobOptions, *,
            progress: Callable[[JobUpdate], None] | None = None,
            should_cancel: Callable[[], bool] | None = None,
            on_submitted: Callable[[str, str], None] | None = None,
            poll_s: float = 0.5, timeout_s: float | None = None) -> JobOutcome:
    """Upload, submit, poll until a terminal state; return the store text (raises on failure/cancel)."""
    report = progress or (lambda _u: None)
    cancelled = should_cancel or (lambda: False)
    report(JobUpdate("uploading", 0.0, "uploading scene"))
    scene = client.upload_scene(glb_path)
    scene_id = str(scene["id"])
    if cancelled():
        raise JobCancelled("cancelled before submission")
    job = client.submit_job(options.payload(scene_id, path_doc))
    if on_submitted:
        on_submitted(scene_id, str(job["id"]))
    job = follow_job(client, job, evals_per_view=options.population * options.generations, progress=report,
                     should_cancel=cancelled, poll_s=poll_s, timeout_s=timeout_s)
    store_id = str(job["store_id"])
    return JobOutcome(str(job["id"]), scene_id, store_id, client.store_text(store_id), scene, job)


def follow_job(client: ServiceClient, job: dict[str, Any], *, evals_per_view: int | None = None,
               progress: Callable[[JobUpdate], None] | None = None,
               should_cancel: Callable[[], bool] | None = None, poll_s: float = 0.5,
               timeout_s: float | None = None) -> dict[str, Any]:
    """Poll a submitted job until it is done and return its last GET /jobs/{id} body. Raises JobFailed,
    JobCancelled, or TimeoutError; a cancel request, the timeout and Ctrl-C (KeyboardInterrupt) cancel the
    job on the service first."""
    report = progress or (lambda _u: None)
    cancelled = should_cancel or (lambda: False)
    job_id = str(job["id"])
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    try:
        while True:
            update = describe(job, evals_per_view)
            report(update)
            if update.state == "done":
                return job
            if update.state == "failed":
                raise JobFailed(f"job {job_id} failed: {job.get('error') or 'no message'}")
            if update.state == "cancelled":
                raise JobCancelled(f"job {job_id} was cancelled")
            if deadline is not None and time.monotonic() > deadline:
                state = cancel_and_wait(client, job_id)
                raise TimeoutError(f"job {job_id} did not finish within {timeout_s} s ({state})")
            # sleep in small steps so a cancel request is honoured quickly
            wake = time.monotonic() + poll_s
            while time.monotonic() < wake:
                if cancelled():
                    report(JobUpdate("cancelling", update.fraction, "cancelling"))
                    state = cancel_and_wait(client, job_id)
                    raise JobCancelled(f"job {job_id} cancelled (service state: {state})")
                time.sleep(min(0.05, poll_s))
            job = client.job(job_id)
    except KeyboardInterrupt:  # the caller is leaving: do not leave the job running on the service
        try:
            cancel_and_wait(client, job_id, wait_s=10.0)
        except Exception:  # the service may already be gone; we are leaving anyway
            pass
        raise


def cancel_and_wait(client: ServiceClient, job_id: str, wait_s: float = 30.0, poll_s: float = 0.1) -> str:
    """DELETE the job, then wait (bounded) until the service says it stopped; returns the last state."""
    try:
        job = client.cancel_job(job_id) or {}
    except ServiceError as err:
        if err.status == 409:  # it finished before the cancel arrived: nothing to stop
            return "already finished"
        raise
    state = str(job.get("state", "?"))
    deadline = time.monotonic() + wait_s
    while state not in TERMINAL and time.monotonic() < deadline:
        time.sleep(poll_s)
        state = str(client.job(job_id).get("state", "?"))
    return state if state in TERMINAL else f"{state}, cancel requested"
