"""The optimiser's entry point: camera path + scene + parameter space -> runtime Pareto store.

Used by the command line, the REST jobs and the add-on's batch path. Steps: leave out parameters the
scene cannot exercise (``sim_core.inert_parameters``), build the octree of per-camera Pareto frontiers
along the path (:mod:`service.octree`), and pack the result into a :class:`ParetoStore`.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import field, make_dataclass
from pathlib import Path
from typing import Any

import numpy as np

import sim_core
from service import options
from service.camera_path import CameraPath
from service.display_pricing import DisplayPricer, DisplayPricing
from service.eval_cache import EvalCache
from service.evaluation import Evaluator, SceneHandle
from service.executors import Executor
from service.nsga import NSGAConfig
from service.octree import Cancelled, OctreeBuilder, OctreeConfig, PathFrames, Progress
from service.params import ParameterSpace
from service.store import ParetoStore

__all__ = ["Cancelled", "OptimizeConfig", "Progress", "optimize_path"]


def _check_config(self: Any) -> None:
    for name, value in options.check({o.name: getattr(self, o.name) for o in options.OPTIONS}).items():
        object.__setattr__(self, name, value)  # as the option's type (an int given for a float ...)
    if not (isinstance(self.fps, (int, float)) and math.isfinite(self.fps) and self.fps > 0):
        raise ValueError(f"fps must be a positive finite number, got {self.fps!r}")
    if self.threads is not None and int(self.threads) < 1:
        raise ValueError(f"threads must be >= 1, got {self.threads!r}")


#: Everything one run needs besides the scene, path and space: every option of
#: :data:`service.options.OPTIONS` (same names and defaults; validated) plus the hardware ``profile``,
#: the frame rate ``fps`` power is measured at and the tracer's ``threads`` per render. Keyword-only.
OptimizeConfig = make_dataclass(
    "OptimizeConfig",
    [(o.name, (o.kind | None) if o.optional else o.kind, field(default=o.default)) for o in options.OPTIONS]
    + [("profile", str, field(default="mobile")), ("fps", float, field(default=30.0)),
       ("threads", int | None, field(default=None))],
    namespace={"__post_init__": _check_config,
               "__doc__": "Options of one optimiser run: service.options.OPTIONS plus profile, fps and "
                          "threads (see service.optimize)."},
    kw_only=True,
)
OptimizeConfig.__module__ = __name__  # (make_dataclass takes module= only from Python 3.12)


def store_pricing(config: OptimizeConfig, display: tuple[int, int]) -> DisplayPricing:
    """How a job (``OptimizeConfig``) prices its store at ``display``: whole frames below
    ``display_tiles_min_pixels``, where the tile estimator would cost about as much and only adds its
    sampling error to the figures the budgets are checked against, else as the job says."""
    small = display[0] * display[1] < config.display_tiles_min_pixels
    estimator = "full" if small else config.display_estimator
    return DisplayPricing(estimator, config.display_fraction, seed=config.seed)


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


def display_resolution(path: CameraPath, height: int | None = None) -> tuple[int, int]:
    """The resolution the path is shown at: its frames' most common one (the first of the most common),
    or ``height`` pixels high with that one's aspect; each side at least 8 pixels (what an error can be
    measured on: a path of 1x1 frames is priced at 8x8)."""
    sizes = [tuple(f.resolution) for f in path.frames]
    w, h = max(dict.fromkeys(sizes), key=sizes.count)
    if height is not None and height != h:
        w, h = round(height * w / h), height
    return max(8, int(w)), max(8, int(h))


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


def optimize_path(scene: Any, path: CameraPath, space: ParameterSpace, config: OptimizeConfig, *,
                  cache: EvalCache, executor: Executor,
                  progress: Callable[[Progress], None] | None = None,
                  should_cancel: Callable[[], bool] | None = None,
                  scratch_dir: Path | None = None, references_dir: Path | None = None) -> ParetoStore:
    """Pareto store for ``path`` in ``scene`` (a ``sim_core.Scene`` or a :class:`SceneHandle`).

    The build's camera references (MBs each at 1280x720) go to ``references_dir`` when given, a folder
    the caller keeps across attempts and removes (the service's job folder: a resumed job reads them
    instead of rendering each camera's Max again), else to a temporary folder in ``scratch_dir`` (None:
    the system's temporary directory) removed at the end.

    Raises :class:`Cancelled` when ``should_cancel`` returns true; everything evaluated so far stays in
    ``cache``, so calling again with the same arguments resumes without re-rendering."""
    t0 = time.perf_counter()
    handle = scene if isinstance(scene, SceneHandle) else SceneHandle(scene)
    if config.skip_inert:
        space = resolve_space(handle.get(), space, path, config.threads)
    frames = path.frames
    vfov = float(np.median([f.vfov for f in frames]))
    aspect = float(np.median([f.aspect for f in frames]))
    width, height = options.eval_resolution(config.eval_width, config.eval_height, aspect)
    display = display_resolution(path, config.display_height)
    # Power and frame time (so which settings keep up with the frame rate) are judged for the size the
    # store's figures are for: the display size when the store is priced there, else the path's own.
    target_pixels = (display[0] * display[1] if config.display_estimator != "preview" else
                     int(np.median([f.resolution[0] * f.resolution[1] for f in frames])))
    evaluator = Evaluator(handle, space, cache=cache, executor=executor, profile=config.profile,
                          fps=config.fps, metric=config.metric, threads=config.threads,
                          target_pixels=target_pixels if config.power_at_path_resolution else None)
    cfg = OctreeConfig(
        threshold_power_w=config.threshold_power_w, threshold_error=config.threshold_error,
        max_depth=config.max_depth, min_depth=config.min_depth, margin=config.margin,
        pad_fraction=config.pad_fraction,
        min_size=config.min_size,
        nsga=NSGAConfig(population=config.population, generations=config.generations, seed=config.seed),
        exhaustive_limit=config.exhaustive_limit, vfov=vfov, width=width, height=height,
        view_sampling=config.view_sampling, path_resolution=config.path_resolution,
        guard_frames=config.guard_frames, guard_radius=config.guard_radius,
        display=None if config.display_estimator == "preview" else display,
        display_points=config.display_points, slow_points=config.slow_points,
        bridge_points=config.bridge_points,
        descent_steps=config.descent_steps,
    )
    pricing = pricer = references = None
    if config.display_estimator != "preview":
        pricing = store_pricing(config, display)
        # each pricing camera's reference, rendered in its first round, read by the later ones
        if references_dir is not None:
            Path(references_dir).mkdir(parents=True, exist_ok=True)
            pricer = DisplayPricer(evaluator, pricing, str(references_dir))
        else:
            references = tempfile.TemporaryDirectory(prefix="render-budget-references-", dir=scratch_dir)
            pricer = DisplayPricer(evaluator, pricing, references.name)
    forwards = targets = None
    if config.view_sampling in ("aimed", "path"):
        forwards, targets = path_targets(handle.get(), path)
    frames_in = PathFrames(path.positions(), forwards, targets,
                           np.stack([np.asarray(f.matrix_world, dtype=np.float64) for f in frames]),
                           np.asarray([f.vfov for f in frames]), np.asarray([f.aspect for f in frames]))
    builder = OctreeBuilder(evaluator, space, frames_in, cfg, progress, should_cancel, pricer)
    try:
        builder.run()
    finally:  # a temporary folder's references are this build's own (a caller's folder stays)
        if references is not None:
            references.cleanup()
    meta = {
        "thresholds": {"power_w": config.threshold_power_w, "error": config.threshold_error},
        "max_depth": config.max_depth,
        "eval_resolution": [width, height],
        "power_pixels": target_pixels if config.power_at_path_resolution else width * height,
        # where the store's error and power figures were measured
        "figures_resolution": list(display) if pricing is not None else [width, height],
        "display_resolution": list(display),
        "display_pricing": pricing.key(config.metric) if pricing is not None else "preview",
        "display_pricing_label": (pricing.label(config.metric) if pricing is not None else
                                  "preview resolution (power scaled by the pixel ratio)"),
        "display_cameras": builder.display_cameras,
        "display_points": builder.display_points,
        # the slow tiers' share of them: at most this many points a frontier (0: all; 1: max quality alone)
        "slow_points": config.slow_points,
        # at most this many settings a frontier priced where its priced errors jumped (0: none), and how
        # many were priced in all
        "bridge_points": config.bridge_points,
        "bridged_points": builder.bridged_points,
        # and how many of the search's probes that kept up were priced (far from max quality only)
        "probed_points": builder.probed_points,
        "near_points": builder.near_points,
        "metric": config.metric,
        # the power figures include it: a lookup at another frame rate reprices power from it
        "static_power_w": sim_core.load_profile(config.profile).static_power_w,
        "view_sampling": config.view_sampling,
        "path_resolution": config.path_resolution,
        "guard_frames": config.guard_frames,
        "guard_radius": config.guard_radius,
        "seed": config.seed,
        "population": config.population,
        "generations": config.generations,
        "fixed_parameters": dict(space.fixed_reasons),
        "evaluations": evaluator.evaluations,
        "cache_hits": evaluator.cache_hits,
        # settings between the most accurate real-time one and Max evaluated for the slow tier (Search.probes)
        "probe_evaluations": builder.search.probes_evaluated,
        "views_optimised": builder.state.views_done,
        "elapsed_s": round(time.perf_counter() - t0, 3),
        "scene": handle.content_hash,
        "executor": getattr(executor, "name", type(executor).__name__),
    }
    if config.descent_steps:  # (stores searched without a descent keep the document they had)
        meta["descent_steps"] = config.descent_steps
        meta["descent_evaluations"] = builder.search.descent_evaluated
    return builder.to_store(profile=config.profile, fps=config.fps, aspect=aspect, meta=meta)

