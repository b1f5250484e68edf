"""The optimiser's entry point: camera path + scene + parameter space -> runtime Pareto store.

Used by the command line, the REST jobs and the add-on's batch path. Steps: leave out parameters the
scene cannot exercise (``sim_core.inert_parameters``), build the octree of per-camera Pareto frontiers
along the path (:mod:`service.octree`), and pack the result into a :class:`ParetoStore`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

import sim_core
from service.camera_path import CameraPath
from service.eval_cache import EvalCache
from service.evaluation import METRICS, Evaluator, SceneHandle
from service.executors import Executor
from service.nsga import NSGAConfig
from service.octree import VIEW_SAMPLING, Cancelled, OctreeBuilder, OctreeConfig, Progress
from service.params import ParameterSpace
from service.pareto_store import ParetoStore

__all__ = ["Cancelled", "OptimizeOptions", "Progress", "optimize_path"]


@dataclass
class OptimizeOptions:
    """Options of one run (defaults follow the paper: population 24, 25 generations).

    ``eval_width``/``eval_height`` set the evaluation resolution; a missing width follows the path's
    aspect. ``min_depth`` splits the nodes the path passes through at least that deep (the paper's
    behaviour is 0: split only where neighbouring frontiers differ). ``margin`` widens nodes (as a
    fraction of their side) when testing whether the path passes through them. ``skip_inert`` asks the
    simulator which parameters cannot matter for the scene. ``power_at_path_resolution`` predicts power
    for the path's resolution (dynamic energy scaled by the pixel ratio) rather than for the small
    evaluation images.

    ``view_sampling="path"`` (default) splits the nodes holding path frames until they are at most
    ``path_resolution`` times the frames' viewing distance wide (``max_depth`` caps it) and optimises
    one sample per (corner, face) the path looks up, at the path camera most like the frames looking it
    up, priced also at ``guard_frames`` more of them. ``"aimed"``/``"axis"`` are the paper's view cubes
    with frontier-difference refinement: there ``max_depth`` is the split depth (keep it at 1-3)."""

    threshold_power_w: float = 0.05
    threshold_error: float = 0.01
    max_depth: int = 6
    min_depth: int = 0
    population: int = 24
    generations: int = 25
    exhaustive_limit: int = 512
    eval_width: int | None = None
    eval_height: int = 36
    profile: str = "mobile"
    fps: float = 30.0
    seed: int = 0
    margin: float = 0.1
    pad_fraction: float = 0.1
    min_size: float = 1.0
    metric: str = "ssim"
    threads: int | None = None
    skip_inert: bool = True
    power_at_path_resolution: bool = True
    view_sampling: str = "path"
    path_resolution: float = 0.25
    guard_frames: int = 2

    def __post_init__(self) -> None:
        for name in ("threshold_power_w", "threshold_error", "fps"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        if not 0 <= self.max_depth <= 12:
            raise ValueError("max_depth must be in 0..12")
        if not 0 <= self.min_depth <= self.max_depth:
            raise ValueError("min_depth must be in 0..max_depth")
        if self.population < 2 or self.generations < 1:
            raise ValueError("population must be >= 2 and generations >= 1")
        if self.exhaustive_limit < 0:
            raise ValueError("exhaustive_limit must be >= 0")
        if self.eval_height < 8 or (self.eval_width is not None and self.eval_width < 8):
            raise ValueError("evaluation resolution must be at least 8x8")
        if self.view_sampling not in VIEW_SAMPLING:
            raise ValueError(f"view_sampling must be one of {VIEW_SAMPLING}")
        if self.metric not in METRICS:
            raise ValueError(f"metric must be one of {METRICS}")
        if not (isinstance(self.path_resolution, (int, float)) and math.isfinite(self.path_resolution)
                and self.path_resolution > 0):
            raise ValueError(f"path_resolution must be positive and finite, got {self.path_resolution!r}")
        if not 0 <= self.guard_frames <= 8:
            raise ValueError("guard_frames must be in 0..8")
        if not (self.margin >= 0 and self.pad_fraction >= 0 and self.min_size > 0):
            raise ValueError("margin and pad_fraction must be >= 0, min_size > 0")


def resolve_space(scene: Any, space: ParameterSpace, path: CameraPath, threads: int | None = None
                  ) -> ParameterSpace:
    """Fix the parameters the simulator reports inert for this scene (verified by rendering there).

    The renders start from the space's maximum, its minimum and a middle setting, so settings that only
    adaptive modes read (similarity threshold, multi-rate) are tried where they can matter; the camera
    is the path's first frame."""
    mq = space.max_quality_indices()
    low = tuple(0 for _ in space.parameters)
    mid = tuple(len(p.values) // 2 for p in space.parameters)
    bases = [space.to_settings(x) for x in (mq, low, mid)]
    f = path.frames[0]
    cam = sim_core.Camera.from_blender(f.matrix_world, f.vfov, 48, max(8, round(48 / f.aspect)))
    candidates = space.as_render_space(free_only=True)
    if not candidates:
        return space
    inert = sim_core.inert_parameters(scene, candidates, cam, bases=bases, threads=threads)
    return space.fix_inert({str(k): str(v) for k, v in dict(inert).items()})


def path_targets(scene: Any, path: CameraPath) -> tuple[np.ndarray, np.ndarray]:
    """Forward vectors (N, 3) of the path's frames and the points their central rays see (N, 3).

    A ray that misses the scene gets the median hit distance of the others (or the path's extent when
    none hits), so open sky still yields a point in front of the camera."""
    frames = path.frames
    eye = np.stack([f.position for f in frames]).astype(np.float64)
    fwd = np.stack([f.direction for f in frames]).astype(np.float64)
    t, _ = scene.intersect(eye.astype(np.float32), fwd.astype(np.float32))
    t = np.asarray(t, dtype=np.float64)
    hit = np.isfinite(t) & (t > 0)
    if np.any(hit):
        fill = float(np.median(t[hit]))
    else:
        fill = max(float(np.ptp(eye, axis=0).max()), 1.0)
    t = np.where(hit, t, fill)
    return fwd, eye + fwd * t[:, None]


def optimize_path(scene: Any, path: CameraPath, space: ParameterSpace, options: OptimizeOptions, *,
                  cache: EvalCache, executor: Executor,
                  progress: Callable[[Progress], None] | None = None,
                  should_cancel: Callable[[], bool] | None = None) -> ParetoStore:
    """Pareto store for ``path`` in ``scene`` (a ``sim_core.Scene`` or a :class:`SceneHandle`).

    Raises :class:`Cancelled` when ``should_cancel`` returns true; everything evaluated so far stays in
    ``cache``, so calling again with the same arguments resumes without re-rendering."""
    t0 = time.perf_counter()
    handle = scene if isinstance(scene, SceneHandle) else SceneHandle(scene)
    if options.skip_inert:
        space = resolve_space(handle.get(), space, path, options.threads)
    frames = path.frames
    vfov = float(np.median([f.vfov for f in frames]))
    aspect = float(np.median([f.aspect for f in frames]))
    height = int(options.eval_height)
    width = int(options.eval_width) if options.eval_width is not None else max(8, round(height * aspect))
    target_pixels = int(np.median([f.resolution[0] * f.resolution[1] for f in frames]))
    evaluator = Evaluator(handle, space, cache=cache, executor=executor, profile=options.profile,
                          fps=options.fps, metric=options.metric, threads=options.threads,
                          target_pixels=target_pixels if options.power_at_path_resolution else None)
    cfg = OctreeConfig(
        threshold_power_w=options.threshold_power_w, threshold_error=options.threshold_error,
        max_depth=options.max_depth, min_depth=options.min_depth, margin=options.margin,
        pad_fraction=options.pad_fraction,
        min_size=options.min_size,
        nsga=NSGAConfig(population=options.population, generations=options.generations, seed=options.seed),
        exhaustive_limit=options.exhaustive_limit, vfov=vfov, width=width, height=height,
        view_sampling=options.view_sampling, path_resolution=options.path_resolution,
        guard_frames=options.guard_frames,
    )
    forwards = targets = None
    if options.view_sampling in ("aimed", "path"):
        forwards, targets = path_targets(handle.get(), path)
    builder = OctreeBuilder(evaluator, space, path.positions(), cfg, progress, should_cancel,
                            path_forwards=forwards, path_targets=targets,
                            path_matrices=np.stack([np.asarray(f.matrix_world, dtype=np.float64)
                                                    for f in frames]),
                            path_vfovs=np.asarray([f.vfov for f in frames]),
                            path_aspects=np.asarray([f.aspect for f in frames]))
    builder.run()
    meta = {
        "thresholds": {"power_w": options.threshold_power_w, "error": options.threshold_error},
        "max_depth": options.max_depth,
        "eval_resolution": [width, height],
        "power_pixels": target_pixels if options.power_at_path_resolution else width * height,
        "metric": options.metric,
        "view_sampling": options.view_sampling,
        "path_resolution": options.path_resolution,
        "guard_frames": options.guard_frames,
        "seed": options.seed,
        "population": options.population,
        "generations": options.generations,
        "fixed_parameters": dict(space.fixed_reasons),
        "evaluations": evaluator.evaluations,
        "cache_hits": evaluator.cache_hits,
        "views_optimised": builder.state.views_done,
        "elapsed_s": round(time.perf_counter() - t0, 3),
        "scene": handle.content_hash,
        "executor": getattr(executor, "name", type(executor).__name__),
    }
    return builder.to_store(profile=options.profile, fps=options.fps, aspect=aspect, meta=meta)


def options_dict(options: OptimizeOptions) -> dict[str, Any]:
    return asdict(options)
