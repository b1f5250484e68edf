"""Submit an optimisation job and follow it to the finished store (pure: HTTP through the client only).

Used by the operator's worker thread (GUI), by its synchronous execute() (background/batch) and by tests.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from service import options as option_schema

from .client import ServiceClient, ServiceError

TERMINAL = ("done", "failed", "cancelled")


class JobFailed(RuntimeError):
    """The service reported the job as failed (message from the service)."""


class JobCancelled(RuntimeError):
    """The job was cancelled (by us or on the service)."""


@dataclass(frozen=True)
class JobRequest:
    """A POST /jobs request besides the scene and the path: the hardware profile, the parameters to
    search, and the optimiser options this job changes (``service.options`` names; the service
    fills in the rest). Validated here with the service's own option schema."""

    profile: str = "mobile"
    parameters: tuple[str, ...] | None = None  # None: all, minus inert (service default)
    options: Mapping[str, Any] = field(default_factory=dict)
    space: Mapping[str, tuple[Any, ...]] | None = None  # values per parameter instead of the default ones

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", option_schema.check(self.options, public_only=True))
        if self.parameters is not None and not self.parameters:
            raise ValueError("select at least one parameter to search")
        if self.space:
            from service.params import renderable_space  # lazy: loads the native core

            renderable_space().with_values(self.space)  # ValueError naming the parameter or value
            object.__setattr__(self, "space", {str(k): tuple(v) for k, v in self.space.items()})

    def option(self, name: str) -> Any:
        """The value the job will run with (the override, else the default)."""
        return self.options.get(name, option_schema.BY_NAME[name].default)

    def payload(self, scene_id: str, path_doc: dict[str, Any]) -> dict[str, Any]:
        body: dict[str, Any] = {"scene_id": scene_id, "camera_path": path_doc, "profile": self.profile,
                                "options": option_schema.only_overrides(self.options)}
        if self.parameters is not None:
            body["parameters"] = list(self.parameters)
        if self.space:
            body["space"] = {k: list(v) for k, v in self.space.items()}
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


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def describe(job: dict[str, Any], evals_per_view: int | None = None) -> JobUpdate:
    """Fraction done and a one-line status from a GET /jobs/{id} body.

    The fraction is the service's own for the whole job (`progress.fraction`: the search and the display
    pricing after it), shown in the text too. A service without it: views done of those planned, which
    reads 100 % while the display pricing runs; the optimiser finishes the views of an octree level
    together, so `views_done` moves in jumps, and with `evals_per_view` (population x generations) the
    fraction also follows the renders inside a level. While it runs, the text also gives the time spent
    (`progress.elapsed_s`, over every attempt of the job) beside the service's time left.
    """
    p = job.get("progress") or {}
    done, planned = int(p.get("views_done") or 0), int(p.get("views_planned") or 0)
    evals = int(p.get("evaluations") or 0) + int(p.get("cache_hits") or 0)
    state = str(job.get("state", "?"))
    whole = p.get("fraction")
    if isinstance(whole, int | float) and not isinstance(whole, bool):
        frac = min(1.0, max(0.0, float(whole)))
    else:
        whole = None
        frac = min(1.0, done / planned) if planned > 0 else 0.0
        if evals_per_view and planned > 0:
            frac = max(frac, min(0.99, evals / (planned * evals_per_view)))
    if state == "done":
        frac = 1.0
    phase = f" [{p['phase']}]" if isinstance(p.get("phase"), str) and state == "running" else ""
    share = f"{100 * frac:.0f} %, " if whole is not None and state == "running" else ""
    text = f"{state}{phase}: {share}{done}/{planned} views, {int(p.get('evaluations') or 0)} evaluations"
    if p.get("cache_hits"):
        text += f" ({int(p['cache_hits'])} cached)"
    if state == "running" and _number(p.get("elapsed_s")):
        # beside the time left, so that a log of these lines shows how the estimates ran out
        text += f", {float(p['elapsed_s']):.0f} s in"
    if p.get("estimate_s") is not None and state == "running":
        text += f", ~{float(p['estimate_s']):.0f} s left"
    if job.get("error"):
        text += f" - {job['error']}"
    return JobUpdate(state, frac, text)


def run_job(client: ServiceClient, scene_path: str | Path, path_doc: dict[str, Any], request: JobRequest, *,
            progress: Callable[[JobUpdate], None] | None = None,
            should_cancel: Callable[[], bool] | None = None,
            on_submitted: Callable[[str, str], None] | None = None,
            poll_s: float = 0.5, timeout_s: float | None = None,
            stall_s: float | None = None) -> JobOutcome:
    """Upload, submit, poll until a terminal state; return the store text (raises on failure/cancel)."""
    report = progress or (lambda _u: None)
    cancelled = should_cancel or (lambda: False)
    report(JobUpdate("uploading", 0.0, "uploading scene"))
    scene = client.upload_scene(scene_path)
    scene_id = str(scene["id"])
    if cancelled():
        raise JobCancelled("cancelled before submission")
    job = client.submit_job(request.payload(scene_id, path_doc))
    if on_submitted:
        on_submitted(scene_id, str(job["id"]))
    per_view = request.option("population") * request.option("generations")
    job = follow_job(client, job, evals_per_view=per_view, progress=report,
                     should_cancel=cancelled, poll_s=poll_s, timeout_s=timeout_s, stall_s=stall_s)
    store_id = str(job["store_id"])
    return JobOutcome(str(job["id"]), scene_id, store_id, client.store_text(store_id), scene, job)


#: Progress fields that move with the clock alone: a job whose other fields stand still is not progressing.
_CLOCK_FIELDS = ("elapsed_s", "estimate_s")


def _progress_mark(job: dict[str, Any]) -> tuple[Any, ...]:
    """What changes when a job gets on: its state and its progress but for the clock's fields."""
    p = job.get("progress") or {}
    return (job.get("state"), *sorted((k, repr(v)) for k, v in p.items() if k not in _CLOCK_FIELDS))


def follow_job(client: ServiceClient, job: dict[str, Any], *, evals_per_view: int | None = None,
               progress: Callable[[JobUpdate], None] | None = None,
               should_cancel: Callable[[], bool] | None = None, poll_s: float = 0.5,
               timeout_s: float | None = None, stall_s: float | None = None) -> dict[str, Any]:
    """Poll a submitted job until it is done and return its last GET /jobs/{id} body. Raises JobFailed,
    JobCancelled, or TimeoutError; a cancel request, a timeout and Ctrl-C (KeyboardInterrupt) cancel the
    job on the service first. ``timeout_s`` bounds the whole wait; ``stall_s`` gives up on a running job
    whose progress has not moved for that long. (A heavy scene's job runs for hours and reports each
    camera priced, so a stall, not the total time, tells a stuck job; a queued job waits its turn.)"""
    report = progress or (lambda _u: None)
    cancelled = should_cancel or (lambda: False)
    job_id = str(job["id"])
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    mark, moved = _progress_mark(job), time.monotonic()
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
            now, current = time.monotonic(), _progress_mark(job)
            if current != mark or update.state != "running":
                mark, moved = current, now
            if deadline is not None and now > deadline:
                state = cancel_and_wait(client, job_id)
                raise TimeoutError(f"job {job_id} did not finish within {timeout_s:g} s ({state})")
            if stall_s is not None and now - moved > stall_s:
                state = cancel_and_wait(client, job_id)
                raise TimeoutError(f"job {job_id} made no progress for {stall_s:g} s ({state})")
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
    """Ask the service to cancel the job, then wait (bounded) until it stopped; returns the last state."""
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
