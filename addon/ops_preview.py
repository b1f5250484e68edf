"""Preview Frame: the current frame rendered with the bundled simulator in this process (with the settings
playback applied, or at maximum quality) into an image datablock, at the scene's render resolution times a
scale, band by band with progress (Esc cancels in the GUI). Analyse Scene: the parameters the scene
cannot exercise, from wherever jobs run."""

from __future__ import annotations

import json
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import bpy
import numpy as np

from service import store as pareto_store

from . import service_process
from .camera_path import camera_vfov, render_resolution, scene_fps
from .core import preview as preview_core
from .core.client import ServiceClient
from .core.engine_settings import pricing_fps
from .core.local_jobs import LocalClient
from .ops_optimize import check_scene, export_scene, fill_parameters

IMAGE_NAME = "Render Budget Preview"


def active_settings(scene: bpy.types.Scene) -> dict[str, Any] | None:
    """The settings playback applied on this frame (None: none yet, i.e. maximum quality)."""
    props = scene.render_budget
    if props.store_text is None or not props.active_indices:
        return None
    store = pareto_store.ParetoStore.from_json(props.store_text.as_string())
    indices = [int(v) for v in props.active_indices.split()]
    return store.settings_of(indices)


def upload_scene_info(scene: bpy.types.Scene, client: ServiceClient | LocalClient) -> dict[str, Any]:
    """Export and upload (deduplicated by content hash); remember the id; returns the answer (id,
    statistics, inert parameters)."""
    with tempfile.TemporaryDirectory(prefix="render-budget-upload-") as tmp:
        info = client.upload_scene(export_scene(scene, tmp))
    scene.render_budget.scene_id = str(info["id"])
    return info


@dataclass
class PreviewJob:
    """What the render needs, read from Blender on the main thread; then rendered on any thread."""

    scene_name: str
    frame: int
    sim_scene: Any
    matrix: list[list[float]]
    vfov: float
    width: int
    height: int
    settings: dict[str, Any] | None
    profile: str
    fps: float
    fraction: float = 0.0
    cancel: threading.Event = field(default_factory=threading.Event)
    result: preview_core.Preview | None = None
    error: BaseException | None = None

    def run(self) -> None:
        try:
            self.result = preview_core.render(
                self.sim_scene, self.matrix, self.vfov, self.width, self.height, settings=self.settings,
                profile=self.profile, fps=self.fps, progress=self._progress, should_cancel=self.cancel.is_set)
        except BaseException as err:  # handed to the main thread, which reports it
            self.error = err

    def _progress(self, fraction: float) -> None:
        self.fraction = fraction


def prepare(scene: bpy.types.Scene, *, use_active: bool = True, scale: float = 1.0) -> PreviewJob:
    """Main thread: check the scene, export it, load it into the core (cached by content)."""
    check_scene(scene)
    w, h = render_resolution(scene)
    w, h = max(4, round(w * scale)), max(4, round(h * scale))
    preview_core.check_size(w, h)
    settings = active_settings(scene) if use_active else None
    # playback's settings are priced at the rate its lookup chose them for, as the render engine does
    fps = pricing_fps(scene.render_budget.target_fps if settings is not None else None, scene_fps(scene))
    with tempfile.TemporaryDirectory(prefix="render-budget-preview-") as tmp:
        sim_scene = preview_core.load_scene(export_scene(scene, tmp))
    cam = scene.camera
    return PreviewJob(scene.name, scene.frame_current, sim_scene, [list(row) for row in cam.matrix_world],
                      camera_vfov(cam, scene), w, h, settings, scene.render_budget.profile or "mobile", fps)


def store_image(job: PreviewJob, fmt: str = "PNG") -> bpy.types.Image:
    """The finished preview as the image datablock IMAGE_NAME, also written to the extension's previews
    folder (PNG or EXR, by Blender's own writer) and packed into the .blend."""
    result = job.result
    if result is None:
        raise RuntimeError("the preview has no image")
    h, w = result.image.shape[:2]
    old = bpy.data.images.get(IMAGE_NAME)
    if old is not None:
        bpy.data.images.remove(old)
    image = bpy.data.images.new(IMAGE_NAME, w, h, float_buffer=True, alpha=False)
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = result.image[::-1]  # Blender's rows start at the bottom
    image.pixels.foreach_set(rgba.ravel())
    directory = Path(bpy.utils.extension_path_user(__package__, path="previews", create=True))
    ext = ".exr" if fmt == "EXR" else ".png"
    image.filepath_raw = str(directory / f"preview_{job.scene_name}_{job.frame}{ext}")
    image.file_format = "OPEN_EXR" if fmt == "EXR" else "PNG"
    image.save()
    image.pack()  # keep the preview in the .blend, independent of the previews folder
    image["render_budget"] = json.dumps({"energy": result.energy, "counters": result.counters,
                                        "settings": job.settings, "frame": job.frame,
                                        "render_s": round(result.render_s, 3)})
    return image


def render_preview(scene: bpy.types.Scene, *, use_active: bool = True, fmt: str = "PNG", scale: float = 1.0,
                   progress: Callable[[float], None] | None = None) -> bpy.types.Image:
    """The whole preview on the calling (main) thread: background mode, batch and tests."""
    job = prepare(scene, use_active=use_active, scale=scale)
    job.result = preview_core.render(job.sim_scene, job.matrix, job.vfov, job.width, job.height,
                                     settings=job.settings, profile=job.profile, fps=job.fps,
                                     progress=progress)
    return store_image(job, fmt)


def _message(image: bpy.types.Image, job: PreviewJob) -> str:
    r = job.result
    return (f"preview in image {image.name!r} ({image.size[0]}x{image.size[1]}): {r.power_w:.3f} W at "
            f"{r.energy['achieved_fps']:.3g} of {job.fps:g} fps on {job.profile}, rendered in "
            f"{r.render_s:.1f} s")


class RENDER_BUDGET_OT_preview(bpy.types.Operator):
    """Render the current frame with the bundled simulator (active or maximum-quality settings) into an
    image (Esc cancels)"""

    bl_idname = "render_budget.preview"
    bl_label = "Preview Frame"

    use_active: bpy.props.BoolProperty(name="Active settings", default=True)  # type: ignore[valid-type]
    format: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Format", items=(("PNG", "PNG", "8-bit sRGB"), ("EXR", "EXR", "linear float (OpenEXR)")))
    scale: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Scale", default=1.0, min=0.01, max=1.0, description="Fraction of the scene's render resolution")

    _job: PreviewJob | None = None
    _thread: threading.Thread | None = None
    _timer: Any = None

    def execute(self, context: bpy.types.Context) -> set[str]:
        wm = context.window_manager
        wm.progress_begin(0, 100)
        try:
            job = prepare(context.scene, use_active=self.use_active, scale=self.scale)
            job.run()
            if job.error is not None:
                raise job.error
            image = store_image(job, self.format)
        except Exception as err:  # report, never leave a half-made image
            self.report({"ERROR"}, f"Preview failed: {err}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        self.report({"INFO"}, _message(image, job))
        return {"FINISHED"}

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if bpy.app.background:
            return self.execute(context)
        try:
            self._job = prepare(context.scene, use_active=self.use_active, scale=self.scale)
        except Exception as err:
            self.report({"ERROR"}, f"Preview failed: {err}")
            return {"CANCELLED"}
        self._thread = threading.Thread(target=self._job.run, name="render-budget-preview", daemon=True)
        self._thread.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        self._status(context, "starting")
        return {"RUNNING_MODAL"}

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        job = self._job
        if event.type == "ESC" and job is not None:
            job.cancel.set()
        if event.type != "TIMER" or job is None or self._thread is None:
            return {"PASS_THROUGH"}
        if self._thread.is_alive():
            self._status(context, f"{100 * job.fraction:.0f} % of {job.width}x{job.height} (Esc to cancel)")
            return {"RUNNING_MODAL"}
        self._finish(context)
        if isinstance(job.error, preview_core.PreviewCancelled):
            self.report({"WARNING"}, "Preview cancelled")
            return {"CANCELLED"}
        if job.error is not None:
            self.report({"ERROR"}, f"Preview failed: {job.error}")
            return {"CANCELLED"}
        try:
            image = store_image(job, self.format)
        except Exception as err:  # report, nothing else to clean up
            self.report({"ERROR"}, f"Preview failed: {err}")
            return {"CANCELLED"}
        self.report({"INFO"}, _message(image, job))
        return {"FINISHED"}

    def cancel(self, context: bpy.types.Context) -> None:
        if self._job is not None:
            self._job.cancel.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
        self._finish(context)

    def _status(self, context: bpy.types.Context, text: str | None) -> None:
        if context.workspace is not None:
            context.workspace.status_text_set(None if text is None else f"Render Budget preview: {text}")

    def _finish(self, context: bpy.types.Context) -> None:
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        self._status(context, None)


class RENDER_BUDGET_OT_analyze_scene(bpy.types.Operator):
    """Export the scene and list the parameters that cannot change it (greyed out, with the reason)"""

    bl_idname = "render_budget.analyze_scene"
    bl_label = "Analyse Scene"

    def execute(self, context: bpy.types.Context) -> set[str]:
        scene = context.scene
        try:
            check_scene(scene)
            info = upload_scene_info(scene, service_process.client_for(context))
        except Exception as err:  # report to the user; nothing changed
            self.report({"ERROR"}, f"Analyse scene failed: {service_process.explain(err)}")
            return {"CANCELLED"}
        store = None
        if scene.render_budget.store_text is not None:
            store = pareto_store.ParetoStore.from_json(scene.render_budget.store_text.as_string())
        fill_parameters(scene, info.get("inert_parameters") or {}, store)
        stats = info.get("stats") or {}
        self.report({"INFO"}, f"{stats.get('triangles', '?')} triangles, "
                              f"{len(info.get('inert_parameters') or {})} inert parameters")
        return {"FINISHED"}


classes = (RENDER_BUDGET_OT_preview, RENDER_BUDGET_OT_analyze_scene)
register, unregister = bpy.utils.register_classes_factory(classes)
