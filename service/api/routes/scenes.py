"""POST /scenes (streamed, size-limited upload of a .glb or a render-budget scene file), GET /scenes (a
page), GET and DELETE /scenes/{id}."""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import struct
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from sim_core.loaders.scene_file import DEFAULT_LIMITS, is_scene_file, read_scene_file
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect

import sim_core
from service.params import default_space
from service.storage import SceneRecord, Storage

from ..checks import deleted
from ..deps import JobsDep, ScenesDep, SettingsDep, StorageDep
from ..errors import ApiError, error_responses
from ..openapi_links import links
from ..schemas import ScenePage, ScenePublic

log = logging.getLogger("render_budget.api")
router = APIRouter(prefix="/scenes", tags=["scenes"])

GLB_MAGIC = b"glTF"
SCENE_FILE_TYPE = "application/vnd.render-budget.scene+zip"
ACCEPTED_TYPES = ("model/gltf-binary", SCENE_FILE_TYPE, "application/octet-stream")

SUFFIXES = {"glb": ".glb", "scene": ".rbscene"}  # storage.SCENE_SUFFIXES

_UPLOAD_ERRORS = error_responses(
    400, 408, 413, 415, 422, e400="neither a glTF binary nor a scene file, truncated, or unreadable",
    e413="upload larger than the configured limit",
    e422="a scene the simulator rejects (NaN, bad indices, empty) or a glTF that is not self-contained (a "
         "URI naming a file: only the binary chunk and data: URIs are read)")


def public(record: SceneRecord) -> ScenePublic:
    return ScenePublic(id=record.id, size=record.size, content_hash=record.content_hash, stats=record.stats,
                       inert_parameters=record.inert, cameras=record.cameras, created=record.created)


def check_glb_header(path: Path, size: int) -> None:
    """Cheap structural checks before the real loader: magic, version, declared length, first chunk."""
    if size < 20:
        raise ApiError(400, f"not a glTF binary (.glb): only {size} bytes")
    with open(path, "rb") as f:
        head = f.read(20)
    magic, version, length = struct.unpack_from("<4sII", head, 0)
    if magic != GLB_MAGIC:
        raise ApiError(400, f"not a glTF binary (.glb): magic is {magic!r}, expected b'glTF'")
    if version != 2:
        raise ApiError(400, f"unsupported glTF binary version {version} (need 2)")
    if length != size:
        raise ApiError(400, f"truncated or padded .glb: header says {length} bytes, received {size}")
    chunk_len, chunk_type = struct.unpack_from("<I4s", head, 12)
    if chunk_type != b"JSON":
        raise ApiError(400, f"malformed .glb: first chunk is {chunk_type!r}, expected b'JSON'")
    if 20 + chunk_len > size:
        raise ApiError(400, f"truncated .glb: JSON chunk of {chunk_len} bytes does not fit")


def default_space_mapping() -> dict[str, list[Any]]:
    """RenderSettings field -> candidate values of the default parameter space (for inert parameters)."""
    return default_space().as_render_space()


def upload_kind(path: Path, size: int, content_type: str) -> str:
    """"glb" or "scene" (a render-budget scene file): what the Content-Type declares, or for
    application/octet-stream what the first bytes say; 400 when the bytes are not what was declared."""
    with open(path, "rb") as f:
        head = f.read(64)
    if content_type == SCENE_FILE_TYPE or (content_type not in ACCEPTED_TYPES[:1] and is_scene_file(head)):
        if not is_scene_file(head):
            raise ApiError(400, f"not a render-budget scene file: it must be a ZIP archive whose first entry "
                                f"is manifest.json (starts with {head[:4]!r})")
        return "scene"
    if content_type == ACCEPTED_TYPES[0] or head.startswith(GLB_MAGIC):
        check_glb_header(path, size)
        return "glb"
    raise ApiError(400, f"neither a glTF binary (.glb) nor a render-budget scene file: magic is "
                        f"{head[:4]!r}")


def analyse_scene(path: Path, kind: str = "glb", max_bytes: int | None = None
                  ) -> tuple[Any, dict[str, Any], dict[str, str]]:
    """Load with the real loader (the only judge of validity) and ask the simulator what is inert.
    A scene file's translation notes (what was approximated) join its statistics as ``notes``."""
    def private(exc: BaseException) -> str:  # the server's file names are nobody's business
        shown = "upload" + SUFFIXES[kind]
        return str(exc).replace(str(path), shown).replace(path.name, shown)

    notes: list[dict[str, str]] = []
    try:
        if kind == "scene":
            limits = DEFAULT_LIMITS if max_bytes is None else dataclasses.replace(DEFAULT_LIMITS,
                                                                                 max_bytes=max_bytes)
            content = read_scene_file(path, limits=limits)
            notes = content.notes
            scene = sim_core.Scene.from_scene_data(content.data)
        else:
            scene = sim_core.Scene.from_gltf(str(path), self_contained=True)  # reads nothing but the upload
    except ValueError as exc:
        raise ApiError(422, f"scene rejected: {private(exc)}") from exc
    except MemoryError as exc:
        raise ApiError(413, "scene too large to load") from exc
    except Exception as exc:  # the file is untrusted; any parser failure is the client's problem
        raise ApiError(400, f"could not read glTF: {type(exc).__name__}: {private(exc)}") from exc
    stats = {k: (v if isinstance(v, int | float | str | bool | list | dict) else str(v))
             for k, v in dict(scene.stats).items()}
    stats["format"] = "scene" if kind == "scene" else "glb"
    if notes:
        stats["notes"] = notes
    inert = {str(k): str(v) for k, v in sim_core.inert_parameters(scene, default_space_mapping()).items()}
    return scene, stats, inert


async def receive_upload(request: Request, storage: Storage, limit: int) -> tuple[Path, str, int]:
    """Stream the body into tmp/ while hashing; stop at the limit (never buffer it all in memory)."""
    declared = request.headers.get("content-length")
    if declared is not None:
        try:
            if int(declared) > limit:
                raise ApiError(413, f"upload of {int(declared)} bytes exceeds the limit of {limit} bytes")
        except ValueError as exc:
            raise ApiError(400, "invalid Content-Length header") from exc
    tmp = storage.new_temp_path(".glb")
    digest = hashlib.sha256()
    size = 0
    try:
        with open(tmp, "wb") as f:
            async for chunk in request.stream():
                size += len(chunk)
                if size > limit:
                    raise ApiError(413, f"upload exceeds the limit of {limit} bytes")
                digest.update(chunk)
                f.write(chunk)
    except ClientDisconnect as exc:
        tmp.unlink(missing_ok=True)
        raise ApiError(400, "upload interrupted: the client disconnected") from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp, digest.hexdigest(), size


_SCENE_LINKS = links(GetScene=("get_scene", "scene_id", "id"), DeleteScene=("delete_scene", "scene_id", "id"))


@router.post(
    "", status_code=status.HTTP_201_CREATED, response_model=ScenePublic, operation_id="upload_scene",
    responses={**_UPLOAD_ERRORS, 201: {"description": "the scene (also for bytes uploaded before)",
                                       "links": _SCENE_LINKS}},
    openapi_extra={"requestBody": {"required": True, "content": {
        t: {"schema": {"type": "string", "format": "binary"}} for t in ACCEPTED_TYPES}}},
)
async def upload_scene(request: Request, storage: StorageDep, scenes: ScenesDep,
                       settings: SettingsDep) -> ScenePublic:
    """Upload a .glb or a render-budget scene file (what the add-on's depsgraph translator writes) as the
    raw request body; its SHA-256 becomes the scene id."""
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype not in ACCEPTED_TYPES:
        raise ApiError(415, f"send the .glb or scene file as the raw body with Content-Type "
                            f"{ACCEPTED_TYPES[0]} or {SCENE_FILE_TYPE} (got {ctype or 'none'!r})")
    tmp, scene_id, size = await receive_upload(request, storage, settings.max_upload_bytes)
    try:
        existing = storage.get_scene(scene_id=scene_id)
        if existing is not None:
            return public(existing)
        kind = upload_kind(tmp, size, ctype)
        scene, stats, inert = await run_in_threadpool(analyse_scene, tmp, kind, settings.max_upload_bytes)
        storage.adopt_scene_file(temp_path=tmp, scene_id=scene_id, suffix=SUFFIXES[kind])
        record = storage.add_scene(scene_id=scene_id, size=size, content_hash=str(scene.content_hash),
                                   stats=stats, inert=inert, cameras=len(scene.cameras))
        scenes.put(scene_id, scene)
        return public(record)
    finally:
        tmp.unlink(missing_ok=True)


@router.get("", response_model=ScenePage, operation_id="list_scenes", responses=error_responses(422))
def list_scenes(storage: StorageDep, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                cursor: Annotated[str | None, Query(max_length=512)] = None) -> ScenePage:
    """Uploaded scenes, newest first, ``limit`` at a time (follow ``next_cursor``)."""
    try:
        page = storage.list_scenes(limit=limit, cursor=cursor)
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc
    return ScenePage(items=[public(r) for r in page.items], next_cursor=page.next_cursor)


@router.get("/{scene_id}", response_model=ScenePublic, operation_id="get_scene",
            responses=error_responses(404))
def get_scene(scene_id: str, storage: StorageDep) -> ScenePublic:
    record = storage.get_scene(scene_id=scene_id)
    if record is None:
        raise ApiError(404, f"scene {scene_id!r} not found")
    return public(record)


@router.delete("/{scene_id}", status_code=status.HTTP_204_NO_CONTENT, response_class=Response,
               operation_id="delete_scene",
               responses=error_responses(404, 409, e409="the scene has queued or running jobs"))
def delete_scene(scene_id: str, jobs: JobsDep) -> Response:
    """Delete the scene file, the scene and its finished jobs. Stores made from it stay (they are
    self-sufficient: delete them with ``DELETE /stores/{id}``); 409 while one of its jobs may still run."""
    return deleted(lambda: jobs.delete_scene(scene_id=scene_id), f"scene {scene_id!r} not found")
