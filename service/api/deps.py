"""Shared objects of a running app, handed to routes as ``Annotated`` dependencies."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, Request

from service.jobs import JobManager, SceneCache
from service.lru import LRUCache
from service.storage import Storage, StoreRecord
from service.store import ParetoStore

from .config import Settings
from .errors import ApiError


class StoreCache:
    """Parsed Pareto stores by id, so a query costs a lookup, not a JSON parse."""

    def __init__(self, storage: Storage, *, capacity: int = 64) -> None:
        self._storage = storage
        self._stores: LRUCache[str, Any] = LRUCache(capacity)

    def drop(self, store_id: str) -> None:
        """Forget a deleted store."""
        self._stores.pop(store_id)

    def get(self, store_id: str) -> Any:
        store = self._stores.get(store_id)
        if store is None:
            record = self._storage.get_store(store_id=store_id)
            if record is None:
                raise ApiError(404, f"store {store_id!r} not found")
            store = ParetoStore.from_json(record.body)
            self._stores.put(store_id, store)
        return store


@dataclass
class AppState:
    settings: Settings
    storage: Storage
    scenes: SceneCache
    jobs: JobManager
    stores: StoreCache


async def get_state(request: Request) -> AppState:
    return request.app.state.render_budget  # type: ignore[no-any-return]


async def get_settings(request: Request) -> Settings:
    return request.app.state.render_budget.settings  # type: ignore[no-any-return]


async def get_storage(request: Request) -> Storage:
    return request.app.state.render_budget.storage  # type: ignore[no-any-return]


async def get_jobs(request: Request) -> JobManager:
    return request.app.state.render_budget.jobs  # type: ignore[no-any-return]


async def get_scenes(request: Request) -> SceneCache:
    return request.app.state.render_budget.scenes  # type: ignore[no-any-return]


async def get_stores(request: Request) -> StoreCache:
    return request.app.state.render_budget.stores  # type: ignore[no-any-return]


# Accessors are ``async`` so FastAPI calls them inline instead of through its thread pool.
SettingsDep = Annotated[Settings, Depends(get_settings)]
StorageDep = Annotated[Storage, Depends(get_storage)]
JobsDep = Annotated[JobManager, Depends(get_jobs)]
ScenesDep = Annotated[SceneCache, Depends(get_scenes)]
StoresDep = Annotated[StoreCache, Depends(get_stores)]


def store_record(store_id: str, storage: StorageDep) -> StoreRecord:
    record = storage.get_store(store_id=store_id)
    if record is None:
        raise ApiError(404, f"store {store_id!r} not found")
    return record


StoreRecordDep = Annotated[StoreRecord, Depends(store_record)]
