"""GET /health: liveness, version, hardware profiles and executor (no token needed)."""

from __future__ import annotations

from fastapi import APIRouter

import service

from ..checks import available_profiles
from ..deps import JobsDep, StorageDep
from ..schemas import Health

router = APIRouter(tags=["health"])


@router.get("/health", response_model=Health)
def health(storage: StorageDep, jobs: JobsDep) -> Health:
    return Health(status="ok", version=service.__version__, profiles=available_profiles(),
                  executor=jobs.executor_description, jobs=storage.count_jobs())
