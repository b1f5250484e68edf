"""GET /health: liveness, version, hardware profiles and executor (no token needed)."""

from __future__ import annotations

from fastapi import APIRouter

import service

from ..deps import JobsDep, StorageDep
from ..schemas import Health

router = APIRouter(tags=["health"])


def available_profiles() -> list[str]:
    """Names of the bundled hardware profiles (empty if the energy model is not importable)."""
    try:
        import sim_core

        return sorted(str(p) for p in sim_core.list_profiles())
    except (ImportError, AttributeError):
        return []


@router.get("/health", response_model=Health)
def health(storage: StorageDep, jobs: JobsDep) -> Health:
    return Health(status="ok", version=service.__version__, profiles=available_profiles(),
                  executor=jobs.executor_description, jobs=storage.count_jobs())
