"""GET /stores/{id} (the Pareto store document) and POST /stores/{id}/query (runtime lookup, sec. 6)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Response

from service.store import TemporalFilter, pack_indices

from ..deps import StoreRecordDep, StoresDep
from ..errors import ApiError, ErrorResponse
from ..schemas import QueryResult, StoreQuery

router = APIRouter(prefix="/stores", tags=["stores"])


@router.get("/{store_id}", responses={200: {"content": {"application/json": {}},
                                            "description": "the store JSON (service.store format)"},
                                       404: {"model": ErrorResponse}})
def get_store(record: StoreRecordDep) -> Response:
    """The store exactly as the optimiser wrote it (load it with ``ParetoStore.from_json``)."""
    return Response(record.body, media_type="application/json", headers={"ETag": f'"{record.id}"'})


def answer_query(store: Any, body: StoreQuery) -> QueryResult:
    """Lookup plus the optional temporal filter; shared by the route and the app's fast path."""
    try:  # the lookup's camera maths is scale-free: huge or tiny but finite orientations are fine
        hit = store.lookup(body.position, direction=body.direction, matrix=body.matrix, fov=body.fov,
                           power_budget=body.power_budget_w, error_budget=body.error_budget,
                           aspect=body.aspect)
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc
    except ArithmeticError as exc:  # extreme but finite numbers the lookup could not handle
        raise ApiError(422, f"camera pose cannot be looked up: {type(exc).__name__}: {exc}") from exc
    indices = tuple(hit.indices)
    filtered = False
    if body.previous is not None:
        prev = tuple(body.previous.indices)
        if len(prev) != len(indices):
            raise ApiError(422, f"previous.indices has {len(prev)} entries, the store has {len(indices)} "
                                "parameters")
        for i, (v, p) in enumerate(zip(prev, store.parameters, strict=True)):
            if v >= len(p.values):
                raise ApiError(422, f"previous.indices[{i}] = {v} is out of range for parameter {p.name!r} "
                                    f"({len(p.values)} values)")
        tf = TemporalFilter(period_s=body.previous.period_s)
        tf.update(prev, 0.0)  # the settings shown when the target changed ...
        tf.update(indices, 0.0)  # ... the new target at that moment ...
        shown = tf.update(indices, body.previous.elapsed_s)  # ... and what Eq. 8 shows elapsed_s later
        filtered = shown != indices
        indices = tuple(shown)
    return QueryResult(
        settings=store.settings_of(indices) if filtered else hit.settings, indices=list(indices),
        packed=pack_indices(indices) if filtered else hit.packed, power_w=hit.power_w, error=hit.error,
        clamped=hit.clamped, infeasible=hit.infeasible, filtered=filtered,
    )


@router.post("/{store_id}/query", response_model=QueryResult,
             responses={404: {"model": ErrorResponse}, 422: {"model": ErrorResponse}})
async def query_store(store_id: str, body: StoreQuery, stores: StoresDep) -> QueryResult:
    """Settings for a camera pose under a power or error budget, optionally through the temporal filter
    (Eq. 8) from the ``previous`` settings, ``elapsed_s`` after the target changed. ``power_w`` and
    ``error`` are the predictions for the target settings."""
    return answer_query(stores.get(store_id), body)
