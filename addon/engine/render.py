"""The "Render Budget GPU" render engine (``RENDER_BUDGET``): the simulated mobile ray-tracing GPU as a
Blender render engine, in-process on the bundled native core.

Final renders (F12, animations, ``bpy.ops.render.render`` in background) trace each frame with the
settings the scene's store picks for that frame's camera under the budget (one temporal filter per
animation, frames in order), or with the manual quality settings; the result carries Combined, Depth,
Normal, Object Index, Sample Kind and Power passes and the settings, predicted and simulated power and
error as image metadata; an animation also writes a per-frame CSV beside its frames.

The viewport (Rendered shading) is :class:`addon.core.viewport.ViewportRenderer` (a worker thread,
coarse to fine); ``view_update`` here reads only what an edit changed (``translate_update``: incremental,
nothing for a camera move) and ``view_draw`` draws the latest image with the ``gpu`` module; both do
nothing in background mode. The worker never calls into Blender: a main-thread timer tags redraws.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import bpy
import numpy as np
from bpy.app.handlers import persistent

from service.store import camera as camera_maths

from .. import preferences
from ..camera_path import camera_vfov, render_resolution, scene_fps
from ..core.engine_frame import PASSES, AnimationLog, CameraView, FrameOutput, RenderCancelled, render_frame
from ..core.engine_frame import animation_csv_path as csv_path_of
from ..core.engine_scene import SceneCache
from ..core.engine_settings import Budget, FrameSettings, SettingsChooser, manual_indices, space
from ..core.viewport import ViewportRenderer
from ..handlers import add_handler, remove_handler
from ..playback import scene_time, store_of
from ..properties import query_values
from ..translate import translate, translate_update
from .properties import manual_identifiers

ENGINE_ID = "RENDER_BUDGET"
ENGINE_LABEL = "Render Budget GPU"
#: Compositor sockets of the passes (Combined first).
PASS_TYPES = {"Combined": "COLOR", "Depth": "VALUE", "Normal": "VECTOR", "IndexOB": "VALUE",
              "Sample Kind": "VALUE", "Power": "VALUE"}


@dataclass
class AnimationSession:
    """One animation render job: its settings chooser (one temporal filter) and its CSV."""

    job: int
    chooser: SettingsChooser
    log: AnimationLog


@dataclass
class LastFrame:
    """The last final frame (the Render Properties panel and tests read it)."""

    frame: int
    output: FrameOutput
    layer_passes: tuple[str, ...]  # the passes of Blender's render result layer
    csv_path: Path | None
    scene_builds: int  # simulator scenes built so far (a camera-only animation builds one)


_final_scenes = SceneCache()  # final renders: the built scene is kept across frames and engine instances
_job = 0  # bumped by render_init: an animation's frames share one session
_sessions: dict[str, AnimationSession] = {}
_viewports: dict[int, ViewportRenderer] = {}  # per viewport engine instance (by id)
last_frame: LastFrame | None = None
#: Test hook: called with the render result layer after the passes are written, before end_result.
inspect_result: Callable[[Any], None] | None = None


# -- which settings -----------------------------------------------------------------------------------
def profile_of(scene: bpy.types.Scene, store: Any) -> str:
    """The hardware profile the engine prices with: the scene's, else the store's, else the default."""
    if scene.render_budget.profile:
        return scene.render_budget.profile
    if store is not None:
        return store.profile
    try:
        return preferences.get().default_profile or "mobile"
    except RuntimeError:
        return "mobile"


def chooser_for(scene: bpy.types.Scene) -> SettingsChooser:
    """A fresh settings chooser for the scene: its store under its budget, or the manual settings."""
    eng, props = scene.render_budget_engine, scene.render_budget
    manual = manual_indices(manual_identifiers(eng))
    store = store_of(scene) if eng.settings_source == "STORE" else None
    budget = None
    if store is not None:
        try:
            budget = Budget(props.budget_mode,
                            props.power_budget if props.budget_mode == "POWER" else props.error_budget)
        except ValueError:
            budget = None  # an unset budget: the manual settings apply (and say why)
    chooser = SettingsChooser(manual, store, budget, props.filter_period, query=query_values(props))
    if eng.settings_source == "MANUAL":
        chooser.note = ""  # the artist's choice, nothing to explain
    return chooser


def _indices(text: str) -> tuple[int, ...]:
    return tuple(int(v) for v in text.split())


def viewport_settings(scene: bpy.types.Scene) -> tuple[FrameSettings, Any]:
    """The settings the viewport shows (and the store they come from): what the playback handler
    applied on this frame (the store's choice under the budget, temporally filtered, as the HUD shows
    it, with the frame-rate target it was looked up for), else a fresh lookup for the scene camera, else
    the manual settings."""
    chooser = chooser_for(scene)
    store, props, cam = chooser.store, scene.render_budget, scene.camera
    if store is None:
        return chooser.manual_settings(), None
    if props.playback_enabled and props.active_indices and not props.playback_status.startswith("error"):
        spc = space()
        active = spc.indices_of(store.settings_of(_indices(props.active_indices)))
        target = spc.indices_of(store.settings_of(_indices(props.target_indices or props.active_indices)))
        return FrameSettings("store", active, props.predicted_power, props.predicted_error, target,
                             props.clamped, props.infeasible, fps_target=props.target_fps or None,
                             meets_fps=None if props.predicted_fps <= 0 else not props.slower_than_fps,
                             priority=props.priority if props.target_fps > 0 else "",
                             predicted_for=store.figures.short()), store
    if cam is None or cam.type != "CAMERA" or cam.data.type != "PERSP":
        return chooser.manual_settings(), store
    w, h = render_resolution(scene)
    return chooser.choose(cam.matrix_world, camera_vfov(cam, scene), w / h, scene_time(scene)), store


def _session(scene: bpy.types.Scene) -> AnimationSession:
    """The running animation job's session for this scene (a new one when a new job started)."""
    session = _sessions.get(scene.name)
    if session is None or session.job != _job:
        if session is not None:
            session.log.close()
        path = csv_path_of(bpy.path.abspath(scene.render.filepath))
        session = AnimationSession(_job, chooser_for(scene), AnimationLog(path))
        _sessions[scene.name] = session
    return session


def _close_sessions() -> None:
    for session in _sessions.values():
        session.log.close()
    _sessions.clear()


@persistent
def on_render_init(*_args: object) -> None:
    global _job
    _job += 1
    _close_sessions()


@persistent
def on_render_done(*_args: object) -> None:
    _close_sessions()


_HANDLERS = ((bpy.app.handlers.render_init, on_render_init),
             (bpy.app.handlers.render_complete, on_render_done),
             (bpy.app.handlers.render_cancel, on_render_done))


def _metric(store: Any) -> str:
    """The error metric a measurement uses: the store's (what its predictions mean), else SSIM."""
    return str((store.meta or {}).get("metric") or "ssim") if store is not None else "ssim"


def _threads(scene: bpy.types.Scene) -> int | None:
    return scene.render_budget_engine.threads or None


# -- the engine ---------------------------------------------------------------------------------------
class RenderBudgetEngine(bpy.types.RenderEngine):
    bl_idname = ENGINE_ID
    bl_label = ENGINE_LABEL
    bl_use_preview = False  # material previews: the simulator has no preview scenes
    bl_use_eevee_viewport = True  # Material Preview shading uses EEVEE; Rendered shading uses this engine
    bl_use_shading_nodes_custom = False  # keep Blender's shader nodes (the Principled BSDF it translates)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._viewport_error: str | None = None
        self._texture: Any = None
        self._drawn: tuple[int, int] | None = None

    def __del__(self) -> None:
        # Blender has removed the engine's data by now (attributes raise ReferenceError): the viewport
        # renderer lives in a module table under the instance's id.
        vp = _viewports.pop(id(self), None)
        if vp is not None:
            vp.close(wait=False)

    # -- final render ---------------------------------------------------------------------------------
    def render(self, depsgraph: bpy.types.Depsgraph) -> None:
        try:
            self._render_frame(depsgraph)
        except RenderCancelled:
            self.update_stats("", f"{ENGINE_LABEL}: cancelled")
        except Exception as exc:  # a render must fail with a message, never a traceback in the UI
            self.report({"ERROR"}, f"{ENGINE_LABEL}: {exc}")
            self.update_stats("", f"{ENGINE_LABEL}: {exc}")

    def _render_frame(self, depsgraph: bpy.types.Depsgraph) -> None:
        global last_frame
        scene = depsgraph.scene
        cam = self.camera_override or scene.camera
        if cam is None or cam.type != "CAMERA":
            raise ValueError("the scene has no active camera")
        eng = scene.render_budget_engine
        w, h = render_resolution(scene)
        vfov = camera_vfov(cam, scene)  # what the store is looked up with; ValueError unless perspective
        r = scene.render
        projection = cam.calc_matrix_camera(depsgraph, x=w, y=h, scale_x=r.pixel_aspect_x,
                                            scale_y=r.pixel_aspect_y)
        trace_vfov, full_w, full_h, x0, y0 = camera_maths.projection_window(projection, w, h)
        notes = ["render region ignored (the whole frame is rendered)"] if r.use_border else []
        self.update_stats("", f"{ENGINE_LABEL} | translating the scene")
        translation = translate(depsgraph, camera=False)
        if self.test_break():
            raise RenderCancelled
        sim_scene = _final_scenes.scene_for(translation.scene_data)
        session = _session(scene) if self.is_animation else None
        chooser = session.chooser if session is not None else chooser_for(scene)
        t = scene_time(scene)
        settings = chooser.choose(cam.matrix_world, vfov, w / h, t)
        fps = settings.pricing_fps(scene_fps(scene))  # the lookup's frame-rate target, else the scene's
        profile = profile_of(scene, chooser.store)
        self.update_stats("", f"{ENGINE_LABEL} | {settings.source} settings | tracing {w}x{h}")
        out = render_frame(sim_scene, CameraView(cam.matrix_world, trace_vfov, full_w, full_h), settings,
                           profile=profile, fps=fps, object_pass_index=translation.pass_indices,
                           transparent=r.film_transparent, threads=_threads(scene),
                           progress=self.update_progress, should_cancel=self.test_break,
                           measure_error=_metric(chooser.store) if eng.measure_error else None)
        if (full_w, full_h) != (w, h):  # lens shift: the camera's window of a larger centred frame
            out = out.window(x0, y0, w, h)
        out.notes = (*out.notes, *notes)
        out.scene_notes = translation.notes_text(limit=6).replace("\n", "; ")
        if translation.warnings and (session is None or session.log.rows == 0):  # once per job
            self.report({"WARNING"}, f"{ENGINE_LABEL}: the simulated scene differs from Blender's: "
                                     f"{translation.notes_text(limit=3)}")
        layer_passes = self._write_result(out, depsgraph.view_layer.name)
        if session is not None:
            session.log.add(scene.frame_current, t, out)
        last_frame = LastFrame(scene.frame_current, out, layer_passes, session.log.path if session else None,
                               _final_scenes.builds)
        self.update_stats("", f"{ENGINE_LABEL} | {out.power_w:.3f} W simulated at {out.achieved_fps:.3g} "
                              f"fps | {settings.text()}")

    def _write_result(self, out: FrameOutput, layer: str) -> tuple[str, ...]:
        h, w = out.combined.shape[:2]
        for name, channels, chan_id in PASSES:
            self.add_pass(name, channels, chan_id, layer=layer)
        result = self.begin_result(0, 0, w, h, layer=layer)
        try:
            passes = result.layers[0].passes
            passes["Combined"].rect.foreach_set(_blender_rows(out.combined))
            for name, _channels, _ids in PASSES:
                passes[name].rect.foreach_set(_blender_rows(out.passes[name]))
            names = tuple(p.name for p in passes)
            if inspect_result is not None:
                inspect_result(result.layers[0])
        finally:
            self.end_result(result)
        stamped = self.get_result()  # metadata set after end_result reaches the written files
        for key, value in out.metadata().items():
            stamped.stamp_data_add_field(key, value)
        return names

    def update_render_passes(self, scene: Any = None, renderlayer: Any = None) -> None:
        """The passes the compositor's Render Layers node offers."""
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for name, channels, chan_id in PASSES:
            self.register_pass(scene, renderlayer, name, channels, chan_id, PASS_TYPES[name])

    # -- viewport (thin: the work is in addon.core.viewport) ---------------------------------------------
    def _viewport_renderer(self, scene: bpy.types.Scene) -> ViewportRenderer:
        vp = _viewports.get(id(self))
        if vp is None:
            vp = _viewports[id(self)] = ViewportRenderer(threads=_threads(scene))
            bpy.app.timers.register(_redraw_poller(weakref.ref(self), vp), first_interval=_REDRAW_POLL_S)
        return vp

    def view_update(self, context: bpy.types.Context, depsgraph: bpy.types.Depsgraph) -> None:
        if bpy.app.background:
            return
        vp = self._viewport_renderer(depsgraph.scene)
        try:
            # incremental: only what the edit changed is read from Blender again
            translation = translate_update(depsgraph, vp.translation_cache, force=vp.scene is None)
            if translation is not None:
                vp.set_scene(translation.scene_data, translation.pass_indices)
                self._viewport_error = None  # (an update that changes nothing keeps a failure shown)
        except Exception as exc:  # shown in the viewport's status; the last good scene stays
            self._viewport_error = str(exc)

    def view_draw(self, context: bpy.types.Context, depsgraph: bpy.types.Depsgraph) -> None:
        if bpy.app.background:
            return
        scene = depsgraph.scene
        region, rv3d = context.region, context.region_data
        vp = self._viewport_renderer(scene)
        if self._viewport_error or vp.scene is None:
            self.update_stats("", f"{ENGINE_LABEL}: {self._viewport_error or 'no scene'}")
            return
        s = scene.render_budget_engine.viewport_scale
        w, h = max(1, round(region.width * s)), max(1, round(region.height * s))
        try:
            settings, store = viewport_settings(scene)
            vp.show(rv3d.view_matrix.inverted(), rv3d.window_matrix, w, h, settings,
                    profile=profile_of(scene, store), fps=settings.pricing_fps(scene_fps(scene)),
                    transparent=scene.render.film_transparent)
        except ValueError as exc:
            self.update_stats("", f"{ENGINE_LABEL}: {exc}")
            return
        frame = vp.latest()
        if frame is not None:
            self._draw(frame, region.width, region.height, scene)
        self.update_stats("", _viewport_status(frame, vp.error, render_resolution(scene)))

    def _draw(self, frame: Any, width: int, height: int, scene: bpy.types.Scene) -> None:
        # lazy: Blender's GPU modules work only with a GPU context (never in background mode)
        import gpu
        from gpu_extras.presets import draw_texture_2d

        if self._drawn != (frame.serial, frame.level):
            h, w = frame.image.shape[:2]
            pixels = gpu.types.Buffer("FLOAT", w * h * 4, _blender_rows(frame.image))
            self._texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=pixels)
            self._drawn = (frame.serial, frame.level)
        gpu.state.blend_set("ALPHA_PREMULT")
        self.bind_display_space_shader(scene)
        draw_texture_2d(self._texture, (0, 0), width, height)
        self.unbind_display_space_shader()
        gpu.state.blend_set("NONE")


#: How often the main thread looks for a new viewport image to draw (s).
_REDRAW_POLL_S = 1.0 / 30.0


def _redraw_poller(engine: weakref.ref[RenderBudgetEngine], vp: ViewportRenderer
                   ) -> Callable[[], float | None]:
    """A timer (Blender's main thread) that asks for a redraw when the worker published a new image: the
    worker thread itself never calls into Blender (not even ``tag_redraw``), so it never runs against
    the interface's own use of Blender's data. Ends with the engine or its viewport renderer."""
    seen = [0]

    def poll() -> float | None:
        e = engine()
        if e is None or not vp.driver.alive:
            return None
        frames = vp.driver.frames
        if frames != seen[0]:
            seen[0] = frames
            try:
                e.tag_redraw()
            except ReferenceError:  # Blender freed the engine meanwhile
                return None
        return _REDRAW_POLL_S

    return poll


def _blender_rows(image: np.ndarray) -> np.ndarray:
    """Flat float32 pixels bottom row first (Blender's order) from an image whose row 0 is the top."""
    return np.ascontiguousarray(image[::-1], dtype=np.float32).ravel()


def _viewport_status(frame: Any, error: str | None, render_size: tuple[int, int]) -> str:
    if error:
        return f"{ENGINE_LABEL}: {error}"
    if frame is None:
        return f"{ENGINE_LABEL} | rendering"
    info = frame.info
    power, rate = info.power_at(render_size[0] * render_size[1])
    text = f"{ENGINE_LABEL} | {info.source}: {info.settings_text} | {power:.3f} W at {rate:.3g} fps"
    if info.predicted_power_w is not None:
        text += (f" (store, {info.predicted_for or 'size unknown'}: {info.predicted_power_w:.3f} W, "
                 f"error {info.predicted_error:.4f})")
    if not frame.final:
        text += f" | refining {frame.level + 1}/{frame.levels}"
    return text


classes = (RenderBudgetEngine,)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    for handlers, fn in _HANDLERS:
        add_handler(handlers, fn)


def unregister() -> None:
    global last_frame
    for handlers, fn in _HANDLERS:
        remove_handler(handlers, fn)
    _close_sessions()
    _final_scenes.clear()
    for vp in _viewports.values():
        vp.close(wait=False)
    _viewports.clear()
    last_frame = None
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
