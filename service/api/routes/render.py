"""POST /render (a preview image with counters and energy report) and POST /evaluate (error and power)."""

from __future__ import annotations

import base64
import dataclasses
import math
import time
from typing import Any

import numpy as np
from fastapi import APIRouter
from sim_core.image import encode_exr, encode_png

import sim_core
from service.evaluation import CameraSpec, Evaluator
from service.params import ParameterSpace, space_holding
from service.store import frame_rate_reached, meets_frame_rate
from service.store.camera import normalised_camera_matrix

from ..checks import scene_or_404
from ..deps import JobsDep, ScenesDep, SettingsDep, StorageDep
from ..errors import ApiError, error_responses
from ..schemas import CameraIn, EvaluateRequest, EvaluateResponse, RenderRequest, RenderResponse

router = APIRouter(tags=["render"])
_ERRORS = error_responses(404, 408, 413, 422, e404="unknown scene")


def camera_matrix(cam: CameraIn, max_pixels: int) -> np.ndarray:
    """The camera's world matrix with unit axes, after the preview size limit."""
    if cam.width * cam.height > max_pixels:
        raise ApiError(422, f"camera resolution {cam.width}x{cam.height} exceeds the limit of {max_pixels} "
                            "pixels")
    try:
        return normalised_camera_matrix(cam.matrix_world)
    except ValueError as exc:  # the schema checked the same already; kept for direct callers
        raise ApiError(422, f"camera: {exc}") from exc


def settings_indices(values: dict[str, Any] | None) -> tuple[ParameterSpace, tuple[int, ...]]:
    """The space holding ``{parameter: value}`` (the names and values a store query returns; the default
    one when it can, see ``space_holding``) and its index vector; parameters left out stay at maximum
    quality."""
    space = space_holding(values)
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


@router.post("/render", response_model=RenderResponse, operation_id="render_preview", responses=_ERRORS)
def render_preview(body: RenderRequest, storage: StorageDep, scenes: ScenesDep,
                   settings: SettingsDep) -> RenderResponse:
    """Render one frame with the simulator; the image comes back base64-encoded next to its counters and
    the energy report of the chosen hardware profile."""
    m = camera_matrix(body.camera, settings.max_render_pixels)
    scene = scene_or_404(storage, scenes, body.scene_id)
    space, indices = settings_indices(body.settings)
    t0 = time.perf_counter()
    try:
        camera = sim_core.Camera.from_blender(m, body.camera.vfov, body.camera.width, body.camera.height)
        result = sim_core.render(scene, camera, space.to_settings(indices), threads=settings.render_threads)
        report = sim_core.price(result, sim_core.load_profile(body.profile), body.fps)
    except ValueError as exc:  # the simulator's own checks: a 422 like every other invalid input
        raise ApiError(422, f"render: {exc}") from exc
    elapsed = time.perf_counter() - t0
    image = np.asarray(result.image, dtype=np.float32)
    data = encode_png(image) if body.format == "png" else encode_exr(image)
    return RenderResponse(
        format=body.format, media_type="image/png" if body.format == "png" else "image/x-exr",
        width=int(image.shape[1]), height=int(image.shape[0]), image_base64=base64.b64encode(data).decode(),
        counters={str(k): int(v) for k, v in dict(result.counters).items()}, energy=_jsonable(report),
        render_time_s=elapsed,
    )


@router.post("/evaluate", response_model=EvaluateResponse, operation_id="evaluate_settings",
             responses=_ERRORS)
def evaluate_settings(body: EvaluateRequest, storage: StorageDep, scenes: ScenesDep, jobs: JobsDep,
                      settings: SettingsDep) -> EvaluateResponse:
    """Error (1 - SSIM against the maximum-quality render of the same camera), power (at the frame rate
    reached) and frame time of settings (``{parameter: value}`` of the renderable space, as a store query
    returns them). Answered from the service's evaluation cache when the same camera, settings, size,
    profile, frame rate and power resolution were evaluated before (by a job or a request); requests
    run concurrently, and the camera's reference is rendered once for all of them."""
    cam = body.camera
    m = camera_matrix(cam, settings.max_render_pixels)
    scene = scene_or_404(storage, scenes, body.scene_id)
    space, indices = settings_indices(body.settings)
    try:
        spec = CameraSpec.from_matrix(m, cam.vfov, cam.width, cam.height)
        pixels = None if body.power_resolution is None else math.prod(body.power_resolution)
        evaluator = Evaluator(scene, space, cache=jobs.eval_cache(), profile=body.profile, fps=body.fps,
                              threads=settings.render_threads, target_pixels=pixels)
        [ev] = evaluator.evaluate([(spec, indices)])
    except ValueError as exc:
        raise ApiError(422, f"evaluate: {exc}") from exc
    t = float(ev.frame_time_s)
    return EvaluateResponse(error=float(ev.error), power_w=float(ev.power_w), frame_time_s=t,
                            fps=frame_rate_reached(t, body.fps), fps_target=float(body.fps),
                            deadline_met=meets_frame_rate(t, body.fps), breakdown=_jsonable(ev.breakdown))
