"""The render engine's viewport (Rendered shading), without bpy or gpu: the engine's ``view_update``
hands it the translated scene when the depsgraph says the scene changed, ``view_draw`` hands it the
view (region camera, size, the frame's settings) and draws :meth:`ViewportRenderer.latest`.

Images come from :class:`addon.core.progressive.ProgressiveDriver` (a worker thread, coarse to fine,
restarted when the view, the scene or the settings change); the simulator scene is built on that
thread too (:class:`addon.core.engine_scene.SceneCache`), so neither translation's BVH build nor a
render ever runs inside a draw call. During playback the playback handler writes each frame's settings
(the store's choice under the budget, temporally filtered) before the viewport draws, so every frame is
rendered with the settings of that frame.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import sim_core
from service.store import camera as camera_maths

from .engine_frame import CameraView, render_frame
from .engine_scene import SceneCache
from .engine_settings import FrameSettings
from .progressive import ProgressiveDriver, ViewFrame, ViewRequest
from .scene_translation.cache import TranslationCache

Matrix = tuple[tuple[float, ...], ...]


def _rows(m: Sequence[Sequence[float]]) -> Matrix:
    return tuple(tuple(float(v) for v in row) for row in m)


@dataclass(frozen=True)
class ViewScene:
    """A translated scene as the viewport holds it: its key (one per translation), the data and each
    object's pass index."""

    key: str
    data: Any
    object_pass_index: tuple[float, ...] = ()


@dataclass(frozen=True)
class ViewPayload:
    scene: ViewScene
    matrix_world: Matrix  # view (camera) to world
    projection: Matrix  # the region's perspective projection
    settings: FrameSettings
    profile: str
    fps: float
    transparent: bool


@dataclass(frozen=True)
class ViewInfo:
    """What the viewport's status line says about the image shown."""

    settings_text: str
    source: str
    static_power_w: float
    dynamic_power_w: float  # at the size rendered, drawn at achieved_fps
    predicted_power_w: float | None
    predicted_error: float | None
    size: tuple[int, int]
    frame_time_s: float  # at the size rendered
    fps: float  # the frame rate asked for
    achieved_fps: float  # the frame rate reached at the size rendered
    predicted_for: str = ""  # the display the predictions hold for (FrameSettings.predicted_for)

    def power_at(self, pixels: int) -> tuple[float, float]:
        """(power W, frame rate reached) scaled to ``pixels`` (dynamic energy and frame time grow with the
        pixel count; the power is drawn at the rate that frame time reaches), so a reduced viewport image
        compares with the store's prediction at the render resolution."""
        ratio = pixels / (self.size[0] * self.size[1])
        energy = self.dynamic_power_w / self.achieved_fps * ratio
        return sim_core.sustained_power(self.static_power_w, energy, self.frame_time_s * ratio, self.fps)


class ViewportRenderer:
    """One per viewport engine instance; ``close()`` when the engine is freed."""

    def __init__(self, on_frame: Callable[[ViewFrame], None] | None = None,
                 scales: tuple[float, ...] = (0.25, 0.5, 1.0), threads: int | None = None) -> None:
        self.threads = threads
        self.translation_cache = TranslationCache()  # what view_update's translations reuse
        self.scenes = SceneCache()
        self.scene: ViewScene | None = None
        self._scene_serial = 0
        self.driver = ProgressiveDriver(self._render, scales, on_frame)

    def set_scene(self, data: Any, object_pass_index: Sequence[float] = ()) -> None:
        """A newly translated scene (the translator decides when the scene changed: the content is not
        hashed here, on the interface's thread; its BVH is built on the worker)."""
        self._scene_serial += 1
        self.scene = ViewScene(f"scene-{self._scene_serial}", data,
                               tuple(float(v) for v in object_pass_index))

    def show(self, matrix_world: Sequence[Sequence[float]], projection: Sequence[Sequence[float]],
             width: int, height: int, settings: FrameSettings, *, profile: str, fps: float,
             transparent: bool = False) -> bool:
        """Render this view (restarting when anything differs from the last); returns whether it
        restarted. ValueError for views the simulator cannot trace (orthographic)."""
        if self.scene is None:
            raise RuntimeError("the viewport has no scene yet (view_update comes first)")
        proj = _rows(projection)
        camera_maths.projection_window(proj, width, height)  # fail here, not on the worker
        payload = ViewPayload(self.scene, _rows(matrix_world), proj, settings, profile, float(fps),
                              bool(transparent))
        key = (self.scene.key, payload.matrix_world, proj, width, height, settings, profile, float(fps),
               bool(transparent))
        return self.driver.update(ViewRequest(key, int(width), int(height), payload))

    def latest(self) -> ViewFrame | None:
        return self.driver.latest()

    @property
    def error(self) -> str | None:
        return self.driver.error

    def close(self, wait: bool = True) -> None:
        self.driver.close(wait)
        self.scenes.clear()
        self.translation_cache.clear()

    def _render(self, payload: ViewPayload, width: int, height: int,
                should_stop: Callable[[], bool]) -> tuple[np.ndarray, ViewInfo]:
        scene = self.scenes.scene_for(payload.scene.data, payload.scene.key)
        vfov, full_w, full_h, x0, y0 = camera_maths.projection_window(payload.projection, width, height)
        windowed = (full_w, full_h) != (width, height)  # a window's power is its Power pass's share
        out = render_frame(scene, CameraView(payload.matrix_world, vfov, full_w, full_h), payload.settings,
                           profile=payload.profile, fps=payload.fps,
                           object_pass_index=payload.scene.object_pass_index or None,
                           transparent=payload.transparent, threads=self.threads, should_cancel=should_stop,
                           passes=windowed)
        if windowed:
            out = out.window(x0, y0, width, height)
        s = payload.settings
        info = ViewInfo(s.text(), s.source, out.power_w - out.dynamic_power_w, out.dynamic_power_w,
                        s.predicted_power_w, s.predicted_error, (width, height), out.frame_time_s, out.fps,
                        out.achieved_fps, s.predicted_for)
        return out.combined, info
