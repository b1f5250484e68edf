"""POST /render (a preview image with counters and energy report) and POST /evaluate (error and power)."""

from __future__ import annotations

import base64
import dataclasses
import io
import math
import time
from typing import Any

import numpy as np
from fastapi import APIRouter

from service.storage import Storage
from service.store.camera import unit_axes

from ..deps import ScenesDep, SettingsDep, StorageDep
from ..errors import ApiError, ErrorResponse
from ..schemas import CameraIn, EvaluateRequest, EvaluateResponse, RenderRequest, RenderResponse
from .jobs import check_profile

router = APIRouter(tags=["render"])
_ERRORS: dict[int | str, dict[str, Any]] = {404: {"model": ErrorResponse}, 422: {"model": ErrorResponse}}


def scene_or_404(storage: Storage, scenes: Any, scene_id: str) -> Any:
    if storage.get_scene(scene_id=scene_id) is None:
        raise ApiError(404, f"scene {scene_id!r} not found")
    return scenes.get(scene_id)


def camera_matrix(cam: CameraIn) -> np.ndarray:
    """The camera's world matrix with unit-length axes (:func:`service.store.camera.unit_axes`)."""
    return unit_axes(cam.matrix_world)


def make_camera(cam: CameraIn, max_pixels: int) -> Any:
    import sim_core

    if cam.width * cam.height > max_pixels:
        raise ApiError(422, f"camera resolution {cam.width}x{cam.height} exceeds the preview limit of "
                            f"{max_pixels} pixels")
    try:
        return sim_core.Camera.from_blender(camera_matrix(cam), cam.vfov, cam.width, cam.height)
    except ValueError as exc:
        raise ApiError(422, f"camera: {exc}") from exc


def settings_indices(values: dict[str, Any] | None) -> tuple[Any, tuple[int, ...]]:
    """The default parameter space and the index vector of ``{parameter: value}`` (the names and values a
    store query returns); parameters left out stay at maximum quality."""
    from service.params import default_space

    space = default_space()
    try:
        return space, space.indices_of(values)
    except ValueError as exc:
        raise ApiError(422, f"settings: {exc}") from None


def _jsonable(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        f = float(value)
        return f if math.isfinite(f) else None
    return str(value)


def encode_png(image: np.ndarray) -> bytes:
    """Linear float RGB -> 8-bit sRGB PNG."""
    from PIL import Image

    x = np.clip(np.nan_to_num(image, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    buf = io.BytesIO()
    Image.fromarray((srgb * 255.0 + 0.5).astype(np.uint8), "RGB").save(buf, format="PNG")
    return buf.getvalue()


def encode_exr(image: np.ndarray, storage: Storage) -> bytes:
    """Linear float RGB -> half-float-free 32-bit EXR (OpenEXR writes files, so go through tmp/)."""
    import OpenEXR

    tmp = storage.new_temp_path(".exr")
    try:
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        with OpenEXR.File(header, {"RGB": np.ascontiguousarray(image, dtype=np.float32)}) as f:
            f.write(str(tmp))
        return tmp.read_bytes()
    finally:
        tmp.unlink(missing_ok=True)


@router.post("/render", response_model=RenderResponse, responses=_ERRORS)
def render_preview(body: RenderRequest, storage: StorageDep, scenes: ScenesDep,
                   settings: SettingsDep) -> RenderResponse:
    """Render one frame with the simulator; the image comes back base64-encoded next to its counters and
    the energy report of the chosen hardware profile."""
    import sim_core

    check_profile(body.profile)
    scene = scene_or_404(storage, scenes, body.scene_id)
    camera = make_camera(body.camera, settings.max_render_pixels)
    space, indices = settings_indices(body.settings)
    rs = space.to_settings(indices)
    t0 = time.perf_counter()
    profile = sim_core.load_profile(body.profile)
    result = sim_core.render(scene, camera, rs, threads=settings.render_threads)
    report = sim_core.price(result, profile, body.fps)
    elapsed = time.perf_counter() - t0
    image = np.asarray(result.image, dtype=np.float32)
    data = encode_png(image) if body.format == "png" else encode_exr(image, storage)
    return RenderResponse(
        format=body.format, media_type="image/png" if body.format == "png" else "image/x-exr",
        width=int(image.shape[1]), height=int(image.shape[0]), image_base64=base64.b64encode(data).decode(),
        counters={str(k): int(v) for k, v in dict(result.counters).items()}, energy=_jsonable(report),
        render_time_s=elapsed,
    )


@router.post("/evaluate", response_model=EvaluateResponse, responses=_ERRORS)
def evaluate_settings(body: EvaluateRequest, storage: StorageDep, scenes: ScenesDep,
                      settings: SettingsDep) -> EvaluateResponse:
    """Error (1 - SSIM against the maximum-quality render of the same camera) and power of settings
    (``{parameter: value}`` of the default space, as a store query returns them)."""
    from service.evaluation import CameraSpec, evaluate

    check_profile(body.profile)
    scene = scene_or_404(storage, scenes, body.scene_id)
    cam = body.camera
    if cam.width * cam.height > settings.max_render_pixels:
        raise ApiError(422, f"camera resolution {cam.width}x{cam.height} exceeds the limit of "
                            f"{settings.max_render_pixels} pixels")
    m = camera_matrix(cam)
    try:
        spec = CameraSpec(eye=tuple(m[:3, 3]), forward=tuple(-m[:3, 2]), up=tuple(m[:3, 1]), vfov=cam.vfov,
                          width=cam.width, height=cam.height)
    except ValueError as exc:
        raise ApiError(422, f"camera: {exc}") from exc
    space, indices = settings_indices(body.settings)
    try:
        ev = evaluate(scene, spec, indices, space, profile=body.profile, fps=body.fps,
                      threads=settings.render_threads)
    except ValueError as exc:
        raise ApiError(422, str(exc)) from exc
    return EvaluateResponse(error=float(ev.error), power_w=float(ev.power_w),
                            frame_time_s=float(ev.frame_time_s), breakdown=_jsonable(ev.breakdown))
