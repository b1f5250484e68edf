"""POST /jobs, GET /jobs/{id}, GET /jobs/{id}/events (server-sent events), DELETE /jobs/{id}."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Header, Request, status
from fastapi.sse import EventSourceResponse, ServerSentEvent

from service.storage import TERMINAL_STATES, JobRecord

from ..deps import JobsDep, SettingsDep, StorageDep
from ..errors import ApiError, ErrorResponse
from ..schemas import JobCreate, JobProgress, JobPublic
from .health import available_profiles

router = APIRouter(prefix="/jobs", tags=["jobs"])


def public(job: JobRecord) -> JobPublic:
    return JobPublic(
        id=job.id, scene_id=job.scene_id, state=job.state,  # type: ignore[arg-type]
        progress=JobProgress(**job.progress), error=job.error, store_id=job.store_id,
        cancel_requested=job.cancel_requested, attempts=job.attempts, created=job.created,
        started=job.started, finished=job.finished,
    )


def job_or_404(job_id: str, storage: StorageDep) -> JobRecord:
    job = storage.get_job(job_id=job_id)
    if job is None:
        raise ApiError(404, f"job {job_id!r} not found")
    return job


JobDep = Annotated[JobRecord, Depends(job_or_404)]


def check_profile(name: str) -> None:
    """Profiles are chosen by name from the bundled list; never a path (no reads outside the package)."""
    names = available_profiles()
    if name not in names:
        raise ApiError(422, f"unknown hardware profile {name!r}; available: {', '.join(names) or 'none'}",
                       details=[{"loc": ["body", "profile"], "msg": "unknown profile",
                                 "type": "value_error"}])


def job_spec(body: JobCreate) -> dict[str, Any]:
    """The request as stored with the job (omitted optional fields left out)."""
    return body.model_dump(mode="json", exclude_none=True)


def check_job_request(body: JobCreate) -> None:
    """Checks that need the optimiser's own definitions (parameter names and values, path validity)."""
    from service.jobs import validate_job_spec

    try:
        validate_job_spec(job_spec(body))
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc


@router.post("", status_code=status.HTTP_201_CREATED, response_model=JobPublic,
             responses={404: {"model": ErrorResponse}, 422: {"model": ErrorResponse}})
def create_job(body: JobCreate, storage: StorageDep, jobs: JobsDep) -> JobPublic:
    """Queue an optimisation of a scene's camera path; returns at once with the job id."""
    if storage.get_scene(scene_id=body.scene_id) is None:
        raise ApiError(404, f"scene {body.scene_id!r} not found; upload it with POST /scenes first")
    check_profile(body.profile)
    check_job_request(body)
    return public(jobs.submit(scene_id=body.scene_id, spec=job_spec(body)))


@router.get("/{job_id}", response_model=JobPublic, responses={404: {"model": ErrorResponse}})
def get_job(job: JobDep) -> JobPublic:
    return public(job)


@router.delete("/{job_id}", response_model=JobPublic,
               responses={404: {"model": ErrorResponse}, 409: {"model": ErrorResponse}})
def cancel_job(job: JobDep, jobs: JobsDep) -> JobPublic:
    """Cancel a queued or running job (idempotent for a cancelled one; 409 for a finished one)."""
    if job.state in ("done", "failed"):
        raise ApiError(409, f"job {job.id!r} already finished ({job.state})")
    updated = jobs.cancel(job_id=job.id)
    assert updated is not None
    return public(updated)


@router.get("/{job_id}/events", response_class=EventSourceResponse,
            responses={404: {"model": ErrorResponse}})
async def job_events(
    job: JobDep, request: Request, storage: StorageDep, jobs: JobsDep, settings: SettingsDep,
    last_event_id: Annotated[str | None, Header()] = None,
) -> AsyncIterator[ServerSentEvent]:
    """Progress as server-sent events (``event``: queued, started, progress, resumed, interrupted, done,
    failed, cancelled; ``id``: sequence number). Ends after the job's final event. Reconnect with
    ``Last-Event-ID`` to continue where the stream stopped."""
    after = 0
    if last_event_id is not None and last_event_id.strip().isdigit():
        after = int(last_event_id.strip())
    seen_version = -1
    last_db_check = 0.0
    while True:
        now = time.monotonic()
        if jobs.version != seen_version or now - last_db_check > 1.0:
            seen_version = jobs.version
            last_db_check = now
            events = storage.events_after(job_id=job.id, after_seq=after)
            for ev in events:
                after = ev.seq
                data: dict[str, Any] = {"job_id": ev.job_id, "seq": ev.seq, "time": ev.created, **ev.data}
                yield ServerSentEvent(id=str(ev.seq), event=ev.kind, data=data)
                if ev.kind in TERMINAL_STATES:
                    return
            if not events:
                current = storage.get_job(job_id=job.id)
                if current is None or (current.state in TERMINAL_STATES
                                       and not storage.events_after(job_id=job.id, after_seq=after)):
                    return
        if await request.is_disconnected():
            return
        await asyncio.sleep(settings.sse_poll_s)
