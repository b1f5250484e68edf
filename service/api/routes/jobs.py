"""POST /jobs, GET /jobs (a page), GET and DELETE /jobs/{id}, POST /jobs/{id}/cancel and
GET /jobs/{id}/events (server-sent events)."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import AsyncIterator
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Header, Query, Request, Response, status
from fastapi.responses import StreamingResponse

from service.jobs import validate_job_spec
from service.storage import TERMINAL_STATES, JobRecord

from ..checks import deleted
from ..deps import JobsDep, SettingsDep, StorageDep
from ..errors import ApiError, error_responses
from ..openapi_links import links
from ..schemas import JobCreate, JobPage, JobProgress, JobPublic, SceneId

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


def job_spec(body: JobCreate) -> dict[str, Any]:
    """The request as stored with the job (omitted optional fields left out)."""
    return body.model_dump(mode="json", exclude_none=True)


def check_job_request(body: JobCreate) -> None:
    """Checks that need the optimiser's own definitions (parameter names and values, path validity)."""
    try:
        validate_job_spec(job_spec(body))
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc


_JOB_LINKS = links(GetJob=("get_job", "job_id", "id"), JobEvents=("job_events", "job_id", "id"),
                   CancelJob=("cancel_job", "job_id", "id"), DeleteJob=("delete_job", "job_id", "id"))


@router.post("", status_code=status.HTTP_201_CREATED, response_model=JobPublic, operation_id="create_job",
             responses={**error_responses(404, 408, 413, 422, e404="unknown scene"),
                        201: {"description": "the queued job", "links": _JOB_LINKS}})
def create_job(body: JobCreate, jobs: JobsDep, storage: StorageDep) -> JobPublic:
    """Queue an optimisation of a scene's camera path; returns at once with the job id. A camera path the
    simulator could not render is refused here (422), not failed later."""
    if storage.get_scene(scene_id=body.scene_id) is None:
        raise ApiError(404, f"scene {body.scene_id!r} not found; upload it with POST /scenes first")
    check_job_request(body)
    try:
        return public(jobs.submit(scene_id=body.scene_id, spec=job_spec(body)))
    except KeyError as exc:  # deleted between the check and the insert
        raise ApiError(404, f"scene {body.scene_id!r} not found") from exc


@router.get("", response_model=JobPage, operation_id="list_jobs", responses=error_responses(422))
def list_jobs(storage: StorageDep, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
              cursor: Annotated[str | None, Query(max_length=512)] = None,
              state: Literal["queued", "running", "done", "failed", "cancelled"] | None = None,
              scene_id: SceneId | None = None) -> JobPage:
    """Jobs, newest first, ``limit`` at a time (follow ``next_cursor``), optionally of one state or scene."""
    try:
        page = storage.page_jobs(limit=limit, cursor=cursor, state=state, scene_id=scene_id)
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc
    return JobPage(items=[public(j) for j in page.items], next_cursor=page.next_cursor)


@router.get("/{job_id}", response_model=JobPublic, operation_id="get_job",
            responses={**error_responses(404),
                       200: {"description": "the job", "links": links(
                           GetStore=("get_store", "store_id", "store_id"),
                           QueryStore=("query_store", "store_id", "store_id"))}})
def get_job(job: JobDep) -> JobPublic:
    return public(job)


@router.post("/{job_id}/cancel", response_model=JobPublic, operation_id="cancel_job",
             responses=error_responses(404, 409, e409="the job already finished (done or failed)"))
def cancel_job(job: JobDep, jobs: JobsDep) -> JobPublic:
    """Cancel a queued or running job (a running one stops at its next check: watch its events);
    idempotent for a cancelled one, 409 for a finished one."""
    if job.state in ("done", "failed"):
        raise ApiError(409, f"job {job.id!r} already finished ({job.state})")
    updated = jobs.cancel(job_id=job.id)
    if updated is None:
        raise ApiError(404, f"job {job.id!r} not found")
    return public(updated)


@router.delete("/{job_id}", status_code=status.HTTP_204_NO_CONTENT, response_class=Response,
               operation_id="delete_job",
               responses=error_responses(404, 409, e409="the job is queued or running: cancel it first"))
def delete_job(job_id: str, jobs: JobsDep) -> Response:
    """Delete a finished job and its events; its store stays. 409 while it is queued or running."""
    return deleted(lambda: jobs.delete_job(job_id=job_id), f"job {job_id!r} not found")


class EventStream(StreamingResponse):
    media_type = "text/event-stream"


def sse(event_id: int, kind: str, data: dict[str, Any]) -> bytes:
    """One server-sent event (data is one line of JSON)."""
    return f"id: {event_id}\nevent: {kind}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n".encode()


KEEPALIVE = b": keepalive\n\n"
_EVENT_ITEM = {"type": "object", "properties": {"data": {"type": "string"}, "event": {"type": "string"},
                                                "id": {"type": "string"}}}


@router.get("/{job_id}/events", response_class=EventStream, operation_id="job_events",
            responses={200: {"description": "the job's events, then the end of the stream",
                             "content": {"text/event-stream": {"itemSchema": _EVENT_ITEM}}},
                       404: {"description": "unknown job", "content": {"application/json": {
                           "schema": {"$ref": "#/components/schemas/ErrorResponse"}}}}})
async def job_events(
    job: JobDep, request: Request, storage: StorageDep, jobs: JobsDep, settings: SettingsDep,
    last_event_id: Annotated[str | None, Header()] = None,
) -> EventStream:
    """Progress as server-sent events (``event``: queued, started, progress, resumed, interrupted, done,
    failed, cancelled; ``id``: sequence number). Ends after the job's final event. Reconnect with
    ``Last-Event-ID`` to continue where the stream stopped. A finished job keeps its state changes and
    its last progress event. A comment line every ``sse_keepalive_s`` keeps idle proxies from closing it."""
    after = 0
    if last_event_id is not None and last_event_id.strip().isdigit():
        after = int(last_event_id.strip())

    async def stream() -> AsyncIterator[bytes]:
        # One generator, no helper tasks: when the client goes, Starlette cancels it and nothing else
        # is left writing to the closed stream.
        nonlocal after
        seen_version = -1
        last_db_check = last_sent = time.monotonic()
        while True:
            now = time.monotonic()
            if jobs.version != seen_version or now - last_db_check > 1.0:
                seen_version = jobs.version
                last_db_check = now
                events = storage.events_after(job_id=job.id, after_seq=after)
                for ev in events:
                    after = ev.seq
                    yield sse(ev.seq, ev.kind, {"job_id": ev.job_id, "seq": ev.seq, "time": ev.created,
                                                **ev.data})
                    last_sent = time.monotonic()
                    if ev.kind in TERMINAL_STATES:
                        return
                if not events:
                    current = storage.get_job(job_id=job.id)
                    if current is None or (current.state in TERMINAL_STATES
                                           and not storage.events_after(job_id=job.id, after_seq=after)):
                        return
            if time.monotonic() - last_sent > settings.sse_keepalive_s:
                yield KEEPALIVE
                last_sent = time.monotonic()
            if await request.is_disconnected():
                return
            await asyncio.sleep(settings.sse_poll_s)

    return EventStream(stream(), headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})
