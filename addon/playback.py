"""Drive the render settings during playback: a persistent frame_change_post handler looks the store up
for the current camera pose and budget, applies the temporal filter on scene time and writes the result
to the scene's properties (read by the panel, the HUD and batch playback)."""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from service import store as pareto_store

from .camera_path import camera_vfov, render_resolution, scene_fps
from .core.playback_logic import PlaybackDriver, PlaybackFrame, StoreCache, frame_flags
from .handlers import add_handler, remove_handler
from .properties import query_values

_cache = StoreCache()
_written: dict[int, tuple] = {}  # per scene: the last answer written to its properties


def scene_time(scene: bpy.types.Scene) -> float:
    """Seconds since the first frame of the range (the temporal filter's clock)."""
    return (scene.frame_current + scene.frame_subframe - scene.frame_start) / scene_fps(scene)


def budget_of(props: bpy.types.PropertyGroup) -> tuple[str, float]:
    mode = props.budget_mode
    return mode, (props.power_budget if mode == "POWER" else props.error_budget)


def _driver(props: bpy.types.PropertyGroup) -> PlaybackDriver:
    text = props.store_text
    return _cache.driver((text.as_pointer(), text.name, props.store_revision), text.as_string,
                         props.filter_period)


def store_of(scene: bpy.types.Scene) -> pareto_store.ParetoStore | None:
    """The scene's store, parsed once per revision (shared with the render engine)."""
    return None if scene.render_budget.store_text is None else _driver(scene.render_budget).store


def flags_of(props: bpy.types.PropertyGroup, *, short: bool = False, transition: bool = True) -> list[str]:
    """The flags playback wrote for this frame, in the words the render engine's frame notes use too
    (:func:`~.core.playback_logic.frame_flags`). ``short``: the HUD's forms; ``transition``: also the
    temporal filter's blending (the HUD shows it; the panels list only what keeps a frame from its
    budget, rate or store)."""
    return frame_flags(infeasible=props.infeasible, slow=props.slower_than_fps, clamped=props.clamped,
                       in_transition=transition and props.playback_status == "blending",
                       fps_target=props.target_fps, priority=props.priority, short=short)


def figures_of(scene: bpy.types.Scene) -> str:
    """The display the store's figures hold for, against the scene's render size, in a few characters
    (``640x360, not 1280x720``; :meth:`service.store.FiguresSize.short`): beside every predicted figure."""
    store = store_of(scene)
    return "" if store is None else store.figures.short(render_resolution(scene))


def show_error(scene: bpy.types.Scene, message: str) -> None:
    """Playback cannot drive this frame: say why (panel and HUD read `playback_status`) and clear the
    previous frame's settings and predictions, which no longer apply."""
    props = scene.render_budget
    status = f"error: {message}"
    if props.playback_status != status or props.active_indices:
        props.active_settings = props.active_indices = props.target_indices = ""
        props.predicted_power = props.predicted_error = props.predicted_fps = props.target_fps = 0.0
        props.clamped = props.infeasible = props.slower_than_fps = False
        props.playback_status = status
    _written.pop(scene.as_pointer(), None)


def update_scene(scene: bpy.types.Scene) -> PlaybackFrame | None:
    """Look up, filter and write this frame's settings; returns what was written (None: nothing to do)."""
    props = scene.render_budget
    text = props.store_text
    if text is None or not props.playback_enabled:
        return None
    cam = scene.camera
    if cam is None:
        show_error(scene, "the scene has no active camera: set one (Scene properties > Camera)")
        return None
    w, h = render_resolution(scene)
    try:
        driver = _driver(props)
        mode, value = budget_of(props)
        frame = driver.step(cam.matrix_world, camera_vfov(cam, scene), w / h, scene_time(scene), mode, value,
                            **query_values(props))
    except ValueError as err:
        show_error(scene, str(err))
        return None
    # Most frames repeat the previous answer: write only when it changed (checked against what the
    # scene holds, so undo or a hand edit of these outputs is corrected on the next frame).
    status = "blending" if frame.in_transition else "on target"
    key = (frame.active_indices, frame.target_indices, frame.predicted_power_w, frame.predicted_error,
           frame.predicted_fps, frame.meets_fps, frame.fps_target, frame.clamped, frame.infeasible, status)
    written = _written.get(scene.as_pointer())
    active_text = " ".join(map(str, frame.active_indices))
    if written == key and props.active_indices == active_text and props.playback_status == status:
        return frame
    props.active_settings = frame.settings_text()
    props.active_indices = active_text
    props.target_indices = " ".join(map(str, frame.target_indices))
    props.predicted_power = frame.predicted_power_w
    props.predicted_error = frame.predicted_error
    props.predicted_fps = frame.predicted_fps or 0.0
    props.target_fps = frame.fps_target or 0.0
    props.slower_than_fps = frame.meets_fps is False
    props.clamped = frame.clamped
    props.infeasible = frame.infeasible
    props.playback_status = status
    _written[scene.as_pointer()] = key
    return frame


def reset() -> None:
    """Forget the parsed store and the filter state (new file, new store)."""
    _cache.clear()
    _written.clear()


@persistent
def on_frame_change(scene: bpy.types.Scene, depsgraph: bpy.types.Depsgraph) -> None:
    update_scene(scene)


@persistent
def on_load(*_args: object) -> None:
    reset()


_HANDLERS = ((bpy.app.handlers.frame_change_post, on_frame_change), (bpy.app.handlers.load_post, on_load))


def register() -> None:
    for handlers, fn in _HANDLERS:
        add_handler(handlers, fn)


def unregister() -> None:
    for handlers, fn in _HANDLERS:
        remove_handler(handlers, fn)
    reset()
