"""One frame of the render engine: traced band by band with the native core, priced on a hardware
profile, and turned into the passes of Blender's render result. Pure (no bpy).

Passes (all at the output resolution, row 0 at the top; ``addon/engine`` flips them for Blender):
Combined (RGBA; alpha 0 where nothing was hit when the film is transparent), Depth (distance from the
camera plane, :data:`BACKGROUND_DEPTH` where nothing was hit), Normal (world-space shading normal),
IndexOB (the hit object's pass index), Sample Kind (0 traced, 1 interpolated, 2 reused from a neighbour)
and Power.

The Power pass shows where the frame's dynamic power goes, tile by tile: the tracer reports every tile's
own activity counters and closest-hit comparisons (they sum to the frame's), the energy model prices
all tiles at once (``sim_core.price_tiles``: ``price`` on arrays; energy is linear in the counts, so the
tiles' energies sum to the frame's), and a pixel holds its tile's power at the frame rate the GPU
reaches (the scene's when the frame keeps up, else its own lower rate: ``sim_core.sustained_power``)
spread evenly over the tile's pixels, in microwatts: the pass sums to the frame's dynamic power (static
power is the same everywhere and left out).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import sim_core
from service.evaluation import image_error

from .engine_settings import FrameSettings, space

#: Blender's depth of background pixels (Cycles and EEVEE write the same).
BACKGROUND_DEPTH = 1.0e10
#: Passes besides Combined: (name, channels, channel ids) as ``RenderEngine.add_pass`` takes them.
PASSES: tuple[tuple[str, int, str], ...] = (
    ("Depth", 1, "Z"),
    ("Normal", 3, "XYZ"),
    ("IndexOB", 1, "X"),
    ("Sample Kind", 1, "X"),
    ("Power", 1, "X"),
)
META_PREFIX = "render_budget."


class RenderCancelled(Exception):
    """The user stopped the render (Esc, or a viewport restart)."""


@dataclass(frozen=True)
class CameraView:
    """A perspective camera: Blender's world matrix (looks down local -Z), vertical fov, output size."""

    matrix_world: Sequence[Sequence[float]]
    vfov: float
    width: int
    height: int

    def camera(self) -> Any:
        m = np.array(self.matrix_world, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError("camera matrix must be a finite 4x4 matrix")
        m[3] = (0.0, 0.0, 0.0, 1.0)
        return sim_core.Camera.from_blender(m, float(self.vfov), int(self.width), int(self.height))

    @property
    def aspect(self) -> float:
        return self.width / self.height


@dataclass
class FrameOutput:
    """A rendered, priced frame and its passes."""

    combined: np.ndarray  # (H, W, 4) float32
    passes: dict[str, np.ndarray]  # name -> (H, W, C) float32, C as in PASSES
    settings: FrameSettings
    profile: str
    fps: float
    power_w: float  # simulated: static + dynamic at achieved_fps (never above the full-speed power)
    dynamic_power_w: float  # at achieved_fps
    frame_time_s: float
    deadline_met: bool
    achieved_fps: float  # the frame rate reached: fps when the deadline is met, else 1 / frame_time_s
    render_resolution: tuple[int, int]
    render_s: float
    counters: dict[str, int] = field(default_factory=dict)
    notes: tuple[str, ...] = ()  # how this frame differs from what was asked (render region, lens shift)
    scene_notes: str = ""  # what the scene translation approximated
    measured_error: float | None = None  # against the maximum-quality frame, when asked for

    def window(self, x0: int, y0: int, width: int, height: int) -> FrameOutput:
        """The ``width`` x ``height`` part at (``x0``, ``y0``) of this frame: how an off-centre camera
        (lens shift) is rendered, as a window of the centred frame traced around it. Power and frame time
        become the window's share (its Power pass; the frame time scaled by the same share of dynamic
        energy), and a note says the frame traced was larger."""
        full_h, full_w = self.combined.shape[:2]
        if not (0 <= x0 and 0 <= y0 and x0 + width <= full_w and y0 + height <= full_h):
            raise ValueError(f"window {width}x{height} at ({x0}, {y0}) is outside the "
                             f"{full_w}x{full_h} frame")
        if "Power" not in self.passes:
            raise ValueError("a window of a frame needs its Power pass (render it with passes)")
        rows, cols = slice(y0, y0 + height), slice(x0, x0 + width)
        passes = {k: np.ascontiguousarray(v[rows, cols]) for k, v in self.passes.items()}
        dynamic = float(passes["Power"].sum(dtype=np.float64)) * 1e-6
        area = width * height / (full_w * full_h)
        share = dynamic / self.dynamic_power_w if self.dynamic_power_w > 0 else area
        frame_time = self.frame_time_s * share
        # the window's own energy, drawn at the rate its own (shorter) frame time reaches
        static = self.power_w - self.dynamic_power_w
        power, reached = sim_core.sustained_power(static, dynamic / self.achieved_fps, frame_time, self.fps)
        passes["Power"] = passes["Power"] * np.float32(reached / self.achieved_fps)
        note = (f"off-centre camera: a {full_w}x{full_h} centred frame was traced and its {width}x{height} "
                f"window kept; power and frame time are the window's share")
        return dataclasses.replace(
            self, combined=np.ascontiguousarray(self.combined[rows, cols]), passes=passes,
            power_w=power, dynamic_power_w=power - static, frame_time_s=frame_time,
            deadline_met=frame_time <= 1.0 / self.fps, achieved_fps=reached, notes=(*self.notes, note))

    def metadata(self) -> dict[str, str]:
        """Image metadata (stamp fields, written into the EXR header / PNG text by Blender)."""
        s = self.settings
        meta = {
            "source": s.source,
            "settings": s.text(),
            "simulated_power_w": f"{self.power_w:.6g}",
            "dynamic_power_w": f"{self.dynamic_power_w:.6g}",
            "frame_time_ms": f"{1e3 * self.frame_time_s:.4g}",
            "deadline_met": "yes" if self.deadline_met else "no",
            "profile": self.profile,
            "fps": f"{self.fps:g}",
            "achieved_fps": f"{self.achieved_fps:.4g}",
            "render_resolution": "{}x{}".format(*self.render_resolution),
        }
        if s.predicted_power_w is not None:
            meta["predicted_power_w"] = f"{s.predicted_power_w:.6g}"
        if s.predicted_error is not None:
            meta["predicted_error"] = f"{s.predicted_error:.6g}"
        if s.predicted_for:  # the display the predictions hold for (the simulated figures: this render's)
            meta["predicted_for"] = s.predicted_for
        if self.measured_error is not None:
            meta["measured_error"] = f"{self.measured_error:.6g}"
        if s.priority:  # looked up in a store: under which frame-rate target and priority
            meta["lookup_fps_target"] = f"{s.fps_target:g}"
            meta["lookup_priority"] = s.priority
        notes = [n for n in (s.note, *self.notes) if n]
        if notes:
            meta["note"] = "; ".join(notes)
        if self.scene_notes:
            meta["scene_notes"] = self.scene_notes
        return {META_PREFIX + k: v for k, v in meta.items()}


def tile_energy(tile_stats: Sequence[Mapping[str, Any]], profile: Any, fps: float, settings: Any = None,
                scene: Any = None) -> np.ndarray:
    """Dynamic energy (J) of each tile: its counters and comparator histogram priced by the energy model
    as a frame's are (same profile, settings and scene; all tiles at once, ``sim_core.price_tiles``).
    ``fps`` is checked but does not change energy."""
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    if not tile_stats:
        return np.zeros(0, dtype=np.float64)
    names = list(tile_stats[0]["counters"])
    if all(list(t["counters"]) == names for t in tile_stats):  # the tracer's tiles: one table at once
        table = np.array([list(t["counters"].values()) for t in tile_stats], dtype=np.uint64)
    else:
        names = sorted({k for t in tile_stats for k in t["counters"]})
        table = np.array([[t["counters"].get(k, 0) for k in names] for t in tile_stats], dtype=np.uint64)
    counters = dict(zip(names, table.T, strict=True))
    histograms = np.stack([np.asarray(t["comparator_histogram"]) for t in tile_stats])
    return sim_core.price_tiles(counters, histograms, profile, settings=settings, scene=scene)


def _edges(n_out: int, n_in: int) -> np.ndarray:
    """Output pixel edge of each input pixel edge (0..n_in), so input tiles partition the output."""
    return np.round(np.arange(n_in + 1) * (n_out / n_in)).astype(np.int64)


def power_pass(tile_stats: Sequence[Mapping[str, Any]], energy_j: np.ndarray, fps: float,
               render_size: tuple[int, int], out_size: tuple[int, int]) -> np.ndarray:
    """(H, W) float32: each tile's power (µW at ``fps``) spread over its pixels at the output size."""
    (rw, rh), (w, h) = render_size, out_size
    xs, ys = _edges(w, rw), _edges(h, rh)
    out = np.zeros((h, w), dtype=np.float64)
    for t, e in zip(tile_stats, energy_j, strict=True):
        x0, y0 = int(t["x0"]), int(t["y0"])
        x1, y1 = x0 + int(t["width"]), y0 + int(t["height"])
        X0, X1, Y0, Y1 = xs[x0], xs[x1], ys[y0], ys[y1]
        pixels = (X1 - X0) * (Y1 - Y0)
        if pixels > 0:
            out[Y0:Y1, X0:X1] = e * fps * 1e6 / pixels
    return out.astype(np.float32)


def _nearest(aov: np.ndarray, h: int, w: int) -> np.ndarray:
    """Nearest-neighbour resize (ids and kinds must not be blended)."""
    ah, aw = aov.shape[:2]
    if (ah, aw) == (h, w):
        return aov
    ys = np.minimum(((np.arange(h) + 0.5) * ah / h).astype(np.int64), ah - 1)
    xs = np.minimum(((np.arange(w) + 0.5) * aw / w).astype(np.int64), aw - 1)
    return aov[ys][:, xs]


def _render(scene: Any, camera: Any, settings: Any, prof: Any, threads: int | None,
            on_band: Callable[[int, int], None]) -> Any:
    """The frame band by band (progress and cancel between bands) on the profile's caches."""
    return sim_core.render_tiled(scene, camera, settings, threads=threads, cache=prof.cache,
                                 texture_cache=prof.texture_cache, progress=on_band)


def render_frame(scene: Any, view: CameraView, frame_settings: FrameSettings, *, profile: str, fps: float,
                 object_pass_index: Sequence[int] | np.ndarray | None = None, transparent: bool = False,
                 threads: int | None = None, progress: Callable[[float], None] | None = None,
                 should_cancel: Callable[[], bool] | None = None,
                 measure_error: str | None = None, passes: bool = True) -> FrameOutput:
    """Render, price and split into passes one frame of ``scene`` (a ``sim_core.Scene``).

    ``progress(fraction)`` and ``should_cancel()`` are called between bands on the calling thread
    (cancelling raises :class:`RenderCancelled`). ``object_pass_index[object_id]`` is the pass index
    of each scene object (default 0 for every object). ``measure_error`` (a metric of the optimiser,
    "ssim"): also render the maximum-quality frame and measure this frame's error against it, as the
    optimiser measured the errors a store predicts. ``passes=False``: the Combined image and the frame's
    power only (the viewport: no per-tile pricing holding the GIL while the interface waits for it).
    """
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    camera = view.camera()
    settings = frame_settings.render_settings()
    prof = sim_core.load_profile(profile)
    spc = space()
    reference_needed = measure_error is not None and frame_settings.indices != spc.max_quality_indices()
    share = 0.5 if reference_needed else 1.0  # of the progress bar, for the frame itself

    def on_band(done: int, total: int, start: float = 0.0) -> None:
        if should_cancel is not None and should_cancel():
            raise RenderCancelled
        if progress is not None:
            progress(start + share * done / total)

    t0 = time.perf_counter()
    result = _render(scene, camera, settings, prof, threads, on_band)
    render_s = time.perf_counter() - t0
    report = sim_core.price(result, prof, float(fps), scene=scene)
    measured = None
    if measure_error is not None:
        measured = 0.0
        if reference_needed:
            reference = _render(scene, camera, spc.to_settings(spc.max_quality_indices()), prof, threads,
                                lambda d, t: on_band(d, t, 0.5))
            measured = image_error(measure_error, reference.image, result.image)

    h, w = view.height, view.width
    aovs = result.aovs
    object_id = _nearest(np.asarray(aovs["object_id"]), h, w).astype(np.int64)
    hit = object_id >= 0
    combined = np.empty((h, w, 4), dtype=np.float32)
    combined[..., :3] = result.image
    combined[..., 3] = np.where(hit, 1.0, 0.0) if transparent else 1.0
    if transparent:
        combined[..., :3] *= combined[..., 3:]  # Blender's render results are premultiplied
    rate = float(report.achieved_fps)  # power is drawn at the frame rate reached (sim_core.sustained_power)
    dynamic_w = float(report.power_w) - prof.static_power_w
    out = FrameOutput(combined, {}, frame_settings, prof.name, float(fps), float(report.power_w), dynamic_w,
                      float(report.frame_time_s), bool(report.deadline_met), rate,
                      tuple(result.render_resolution), render_s,
                      {k: int(v) for k, v in result.counters.items()}, measured_error=measured)
    if not passes:
        return out
    depth = np.where(hit, _nearest(np.asarray(aovs["depth"]), h, w), BACKGROUND_DEPTH)
    n_ids = int(object_id.max()) + 1 if hit.any() else 1
    lookup = np.zeros(n_ids, dtype=np.float32)
    if object_pass_index is not None:
        known = np.asarray(object_pass_index, dtype=np.float32)[:n_ids]
        lookup[: known.size] = known
    index = np.where(hit, lookup[np.maximum(object_id, 0)], 0.0)
    energy = tile_energy(result.tile_stats, prof, float(fps), settings, scene)
    normal = np.where(hit[..., None], _nearest(np.asarray(aovs["normal"]), h, w), 0.0)
    power = power_pass(result.tile_stats, energy, rate, result.render_resolution, (w, h))
    out.passes = {
        "Depth": depth.astype(np.float32)[..., None],
        "Normal": normal.astype(np.float32),
        "IndexOB": index.astype(np.float32)[..., None],
        "Sample Kind": _nearest(np.asarray(aovs["sample_kind"]), h, w).astype(np.float32)[..., None],
        "Power": power[..., None],
    }
    return out


CSV_COLUMNS_BEFORE = ("frame", "time_s", "source")
CSV_COLUMNS_AFTER = ("predicted_power_w", "simulated_power_w", "predicted_error", "measured_error",
                     "frame_time_ms", "achieved_fps",
                     "deadline_met", "in_transition", "clamped", "infeasible", "render_s",
                     "fps_target", "meets_fps", "priority", "image_resolution", "predicted_for")


class AnimationLog:
    """The per-frame CSV of an animation render: one row per frame, written (and flushed) as soon as the
    frame is rendered, so a cancelled render keeps the frames it made."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.columns = (*CSV_COLUMNS_BEFORE, *space().names, *CSV_COLUMNS_AFTER)
        self._fh = self.path.open("w", newline="", encoding="utf-8")
        self._writer = csv.DictWriter(self._fh, fieldnames=self.columns)
        self._writer.writeheader()
        self._fh.flush()
        self.rows = 0

    def add(self, frame: int, time_s: float, out: FrameOutput) -> None:
        s = out.settings
        row: dict[str, Any] = {"frame": frame, "time_s": f"{time_s:.6g}", "source": s.source}
        row.update(s.values())
        row.update({
            "predicted_power_w": "" if s.predicted_power_w is None else f"{s.predicted_power_w:.6g}",
            "simulated_power_w": f"{out.power_w:.6g}",
            "predicted_error": "" if s.predicted_error is None else f"{s.predicted_error:.6g}",
            "measured_error": "" if out.measured_error is None else f"{out.measured_error:.6g}",
            "frame_time_ms": f"{1e3 * out.frame_time_s:.4g}",
            "achieved_fps": f"{out.achieved_fps:.4g}",
            "deadline_met": int(out.deadline_met),
            "in_transition": int(s.in_transition),
            "clamped": int(s.clamped),
            "infeasible": int(s.infeasible),
            "render_s": f"{out.render_s:.3f}",
            # the store lookup's frame-rate target and priority, and whether the store said the settings
            # keep up with that target (blank for manual settings or a store before frame times)
            "fps_target": "" if s.fps_target is None else f"{s.fps_target:g}",
            "meets_fps": "" if s.meets_fps is None else int(s.meets_fps),
            "priority": s.priority,
            # the image simulated_power_w was priced for (traced at its resolution scale), and the display
            # the predictions hold for
            "image_resolution": f"{out.combined.shape[1]}x{out.combined.shape[0]}",
            "predicted_for": s.predicted_for,
        })
        self._writer.writerow(row)
        self._fh.flush()
        self.rows += 1

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()



def animation_csv_path(output_path: str | Path) -> Path:
    """Where an animation's per-frame CSV goes: beside the frames, named after their prefix
    (``render/shot_`` -> ``render/shot_render_budget.csv``; a folder -> ``render_budget.csv`` in it)."""
    text = str(output_path)
    folder, name = (text, "") if text.endswith(("/", "\\")) else (str(Path(text).parent), Path(text).name)
    name = name.replace("#", "")
    stem, ext = name.rsplit(".", 1) if "." in name else (name, "")
    if ext.lower() not in ("", "png", "exr", "jpg", "jpeg", "tif", "tiff", "webp", "bmp", "hdr"):
        stem = name  # a dot that is not an image extension belongs to the name
    if stem and not stem.endswith(("_", "-", ".", " ")):
        stem += "_"
    return Path(folder) / f"{stem}render_budget.csv"
