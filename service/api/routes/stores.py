"""GET /stores (a page), GET and DELETE /stores/{id} (the Pareto store document),
POST /stores/{id}/query (runtime lookup, sec. 6) and POST /stores/{id}/verify (its promises measured)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status

from service.camera_path import CameraPath
from service.options import query_fields
from service.storage import StoreRecord
from service.store import TemporalFilter
from service.verify import verify_store

from ..checks import deleted, scene_or_404
from ..deps import ScenesDep, SettingsDep, StorageDep, StoreRecordDep, StoresDep
from ..errors import ApiError, error_responses
from ..lean_route import LeanJsonRoute
from ..schemas import QueryResult, SceneId, StorePage, StorePublic, StoreQuery, VerifyRequest, VerifyResult

router = APIRouter(prefix="/stores", tags=["stores"])


def public(record: StoreRecord) -> StorePublic:
    return StorePublic(id=record.id, scene_id=record.scene_id, job_id=record.job_id, size=record.size,
                       created=record.created)


@router.get("", response_model=StorePage, operation_id="list_stores", responses=error_responses(422))
def list_stores(storage: StorageDep, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                cursor: Annotated[str | None, Query(max_length=512)] = None,
                scene_id: SceneId | None = None) -> StorePage:
    """Stores (without their bodies), newest first, ``limit`` at a time (follow ``next_cursor``)."""
    try:
        page = storage.list_stores(limit=limit, cursor=cursor, scene_id=scene_id)
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc
    return StorePage(items=[public(r) for r in page.items], next_cursor=page.next_cursor)


@router.get("/{store_id}", operation_id="get_store",
            responses={200: {"content": {"application/json": {}},
                             "description": "the store JSON (service.store format)"},
                       **error_responses(404)})
def get_store(record: StoreRecordDep) -> Response:
    """The store exactly as the optimiser wrote it (load it with ``ParetoStore.from_json``)."""
    return Response(record.body, media_type="application/json", headers={"ETag": f'"{record.id}"'})


@router.delete("/{store_id}", status_code=status.HTTP_204_NO_CONTENT, response_class=Response,
               operation_id="delete_store", responses=error_responses(404))
def delete_store(store_id: str, storage: StorageDep, stores: StoresDep) -> Response:
    """Delete a store; the jobs that made it keep its id (and get 404 for it from then on)."""
    answer = deleted(lambda: storage.delete_store(store_id=store_id), f"store {store_id!r} not found")
    stores.drop(store_id)
    return answer


@router.post("/{store_id}/verify", response_model=VerifyResult, operation_id="verify_store",
             responses=error_responses(404, 422))
def verify(body: VerifyRequest, record: StoreRecordDep, storage: StorageDep, scenes: ScenesDep,
           stores: StoresDep, settings: SettingsDep) -> VerifyResult:
    """Render ``frames`` path frames, spread evenly, at the path's resolution (or ``resolution``) with the
    settings the store picks under the budget (and the query options ``fps``, ``priority``,
    ``error_margin`` and ``power_margin``, as a query takes them; measured at that frame rate), and set
    the measured error and power against the store's predictions: per frame, the share within budget,
    the worst frames. Runs while the request waits (about two full-size renders a frame)."""
    try:
        path = CameraPath.from_dict(body.camera_path.model_dump())
    except ValueError as exc:
        raise ApiError(422, f"camera_path: {exc}") from exc
    sizes = [body.resolution] if body.resolution is not None else [f.resolution for f in path.frames]
    biggest = max(int(w) * int(h) for w, h in sizes)
    if biggest > settings.max_render_pixels:
        raise ApiError(422, f"verify renders {biggest} pixels a frame, over the limit of "
                            f"{settings.max_render_pixels} pixels (give a smaller resolution)")
    scene = scene_or_404(storage, scenes, record.scene_id)
    try:
        report = verify_store(scene, stores.get(record.id), path, error_budget=body.error_budget,
                              power_budget=body.power_budget_w, frames=body.frames,
                              resolution=body.resolution, threads=settings.render_threads,
                              **query_fields(body))
    except ValueError as exc:
        raise ApiError(422, f"verify: {exc}") from exc
    return VerifyResult(**report.to_dict())


def answer_query(store: Any, body: StoreQuery) -> QueryResult:
    """Lookup plus the optional temporal filter."""
    try:  # the lookup's camera maths is scale-free: huge or tiny but finite orientations are fine
        hit = store.lookup(body.position, direction=body.direction, matrix=body.matrix, fov=body.fov,
                           power_budget=body.power_budget_w, error_budget=body.error_budget,
                           aspect=body.aspect, **query_fields(body))
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc
    except ArithmeticError as exc:  # extreme but finite numbers the lookup could not handle
        raise ApiError(422, f"camera pose cannot be looked up: {type(exc).__name__}: {exc}") from exc
    target = tuple(hit.indices)
    shown = target
    where = store.figures.fields()  # which display the figures hold for, with every answer
    if body.previous is not None:
        prev = tuple(body.previous.indices)
        if len(prev) != len(target):
            raise ApiError(422, f"previous.indices has {len(prev)} entries, the store has {len(target)} "
                                "parameters")
        for i, (v, p) in enumerate(zip(prev, store.parameters, strict=True)):
            if v >= len(p.values):
                raise ApiError(422, f"previous.indices[{i}] = {v} is out of range for parameter {p.name!r} "
                                    f"({len(p.values)} values)")
        points = {pt.indices: pt for pt in store.budget_points(hit)}
        tf = TemporalFilter(period_s=body.previous.period_s)
        tf.update(prev, 0.0)  # the settings shown when the target changed ...
        errors = {k: pt.error for k, pt in points.items()}
        tf.update(target, 0.0, errors)  # ... the new target at that moment ...
        shown = tf.update(target, body.previous.elapsed_s, errors)  # ... and what it shows later
    if shown == target:
        return QueryResult(
            settings=hit.settings, indices=list(target), packed=hit.packed, power_w=hit.power_w,
            error=hit.error, clamped=hit.clamped, infeasible=hit.infeasible, filtered=False,
            target_indices=list(target), frame_time_s=hit.frame_time_s, fps=hit.fps,
            fps_target=hit.fps_target, meets_fps=hit.meets_fps, priority=hit.priority,
            error_margin=hit.error_margin, power_margin=hit.power_margin,
            expected_power_w=hit.expected_power_w, expected_error=hit.expected_error, **where)
    pt = points[shown]
    expected_error, expected_power = store.expected(hit, pt)
    return QueryResult(
        settings=store.settings_of(shown), indices=list(shown), packed=pt.packed, power_w=pt.power_w,
        error=pt.error, clamped=hit.clamped, infeasible=hit.infeasible, filtered=True,
        target_indices=list(target), frame_time_s=pt.frame_time_s, fps=pt.fps, fps_target=hit.fps_target,
        meets_fps=pt.meets_fps, priority=hit.priority, error_margin=hit.error_margin,
        power_margin=hit.power_margin, expected_power_w=expected_power,
        expected_error=expected_error, **where)


async def query_store(store_id: str, body: StoreQuery, request: Request) -> QueryResult:
    """Settings for a camera pose under a power or error budget, optionally through the temporal filter
    from the ``previous`` settings, ``elapsed_s`` after the target changed: Eq. 8's pace, but always a
    point of this view's frontier that keeps the budget (when the target does). ``fps`` asks for another
    frame rate than the store's (power repriced for it); ``priority`` says what gives way when no setting
    keeps both the budget and that rate: ``frame_rate`` (default: the budget) or ``budget`` (the frame
    rate; ``meets_fps`` false), echoed as ``priority``. ``power_w``, ``error``, ``frame_time_s``, ``fps``
    and ``meets_fps`` are the predictions for the returned settings, for the display size
    ``figures_resolution`` (``figures_kind`` display; preview: the search's small renders)."""
    return answer_query(request.app.state.render_budget.stores.get(store_id), body)


# The per-frame call of a runtime: served without FastAPI's parameter solving (service.api.lean_route),
# and matched before the other store routes.
router.add_api_route("/{store_id}/query", query_store, methods=["POST"], response_model=QueryResult,
                     operation_id="query_store", route_class_override=LeanJsonRoute,
                     responses=error_responses(404, 408, 413, 422))
router.routes.insert(0, router.routes.pop())
