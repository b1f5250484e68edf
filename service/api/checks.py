"""What several routes share: the hardware profiles, scenes by id, the answer of a delete."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from starlette.responses import Response

from service.jobs import SceneCache
from service.storage import Conflict, Storage

from .errors import ApiError
from .schemas import PROFILES


def available_profiles() -> list[str]:
    """Names of the bundled hardware profiles (the only ones a request may name)."""
    return list(PROFILES)


def scene_or_404(storage: Storage, scenes: SceneCache, scene_id: str) -> Any:
    """The loaded scene, or a 404 (also when it was deleted a moment ago)."""
    if storage.get_scene(scene_id=scene_id) is not None:
        try:
            return scenes.get(scene_id)
        except FileNotFoundError:
            pass
    raise ApiError(404, f"scene {scene_id!r} not found")


def deleted(delete: Callable[[], bool], missing: str) -> Response:
    """204 when ``delete()`` deleted something, 404 (``missing``) when there was nothing, 409 when
    something still needs it (``Conflict``)."""
    try:
        found = delete()
    except Conflict as exc:
        raise ApiError(409, str(exc)) from exc
    if not found:
        raise ApiError(404, missing)
    return Response(status_code=204)
