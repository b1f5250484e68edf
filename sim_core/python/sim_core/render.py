"""render() and render_stereo(): the tile-based tracer with its activity counters.

A RenderResult carries everything the energy model prices (counters, per-tile statistics, comparator
histogram) next to the image and its AOVs, so `price(result, profile, fps)` needs nothing else.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _core
from .camera import Camera
from .image import upsample_bilinear
from .scene import Scene, _threads
from .settings import RenderSettings

# Default node/triangle cache of the T&I unit model when no hardware profile provides one.
DEFAULT_CACHE = (32 * 1024, 64, 4)
# Default texture cache of the shading cores (the native kDefaultTextureCache).
DEFAULT_TEXTURE_CACHE = (16 * 1024, 64, 4)

COUNTER_NAMES: tuple[str, ...] = (
    "rays_primary",
    "rays_shadow",
    "rays_reflection",
    "rays_refraction",
    "rays_ao",
    "rays_glossy",
    "rays_total",
    "bvh_node_visits",
    "triangle_tests",
    "shading_evals",
    "raygen_evals",
    "similarity_checks",
    "interpolations",
    "reprojections",
    "tile_buffer_reads",
    "tile_buffer_writes",
    "framebuffer_bytes",
    "gbuffer_prefetch_bytes",
    "cache_accesses",
    "cache_misses",
    "dram_bytes_read",
    "closest_hit_comparisons",
    "env_lookups",
    "env_filtered_lookups",
    "samples_traced",
    "samples_interpolated",
    "samples_reused",
    "pixels",
    "rays_alpha",
    "alpha_tests",
    "area_light_evals",
    "texture_fetches",
    "texel_reads",
    "texture_cache_misses",
    "texture_dram_bytes",
    "env_sh_evals",
    "resolve_taps",
    "resolve_bytes",
    "ambient_filter_taps",
)


# Kinds of TracedRays.kind (the native TracedKind): shadow and ao rays are any-hit queries, the rest closest
# hit.
RAY_KINDS: tuple[str, ...] = ("primary", "shadow", "reflection", "refraction", "ao", "glossy")
ANY_HIT_KINDS: tuple[str, ...] = ("shadow", "ao")


@dataclass(frozen=True)
class TracedRays:
    """Every ray a render traced (``render(..., log_rays=True)``), tile by tile in tile order: what a
    benchmark replays through another tracer. Ray i spans (0, tmax[i]) along directions[i] (not unit)."""

    origins: np.ndarray  # (N, 3) float32
    directions: np.ndarray  # (N, 3) float32
    tmax: np.ndarray  # (N,) float32, inf for unbounded rays
    kind: np.ndarray  # (N,) uint8 index into RAY_KINDS

    def of_kind(self, name: str) -> np.ndarray:
        """Boolean mask of the rays of one kind (a RAY_KINDS name)."""
        return self.kind == RAY_KINDS.index(name)


@dataclass
class RenderResult:
    """One rendered frame.

    image: (H, W, 3) float32 linear RGB at the camera resolution (bilinearly upscaled when the settings
      render at a reduced resolution_scale). aovs: depth (camera-space, inf on miss), normal, object_id
      (-1 on miss), sample_kind (0 traced, 1 interpolated, 2 reused), all at the render resolution.
    counters: activity counts (COUNTER_NAMES). tile_stats: one dict per tile. comparator_histogram:
      closest-hit comparisons by compute-chain length (0..24). multirate_state: pass as `previous=`.
    Every tile's own counters and histogram are in its ``tile_stats`` entry (``counters``,
    ``comparator_histogram``); ``tile_counters`` / ``tile_histograms`` give them as arrays.
    """

    image: np.ndarray
    aovs: dict[str, np.ndarray]
    counters: dict[str, int]
    tile_stats: list[dict[str, Any]]
    comparator_histogram: np.ndarray
    multirate_state: Any
    settings: RenderSettings
    camera: Camera
    render_resolution: tuple[int, int]  # (width, height) actually traced
    extra: dict[str, Any] = field(default_factory=dict)
    rays: TracedRays | None = None  # with render(..., log_rays=True)

    @property
    def tile_counters(self) -> np.ndarray:
        """(tiles, len(COUNTER_NAMES)) uint64: every tile's own counters in tile order (each tile's caches
        start cold, so the rows sum to ``counters`` exactly: a sample of tiles prices a sample of the
        frame)."""
        return np.asarray([[t["counters"][k] for k in COUNTER_NAMES] for t in self.tile_stats],
                          dtype=np.uint64).reshape(len(self.tile_stats), len(COUNTER_NAMES))

    @property
    def tile_histograms(self) -> np.ndarray:
        """(tiles, 25) uint64: every tile's comparator histogram (rows sum to the frame's)."""
        return np.asarray([t["comparator_histogram"] for t in self.tile_stats],
                          dtype=np.uint64).reshape(len(self.tile_stats), -1)


@dataclass
class StereoResult:
    left: RenderResult
    right: RenderResult
    reuse_ratio: float  # right-eye pixels reused from the left eye / right-eye pixels
    holes: int = 0  # right-eye pixels nothing reprojected into (disocclusion, out of frame)
    silhouettes: int = 0  # pixels at object/depth edges of the reprojected image, traced
    depth_mismatches: int = 0  # farther samples showing through a reprojected nearer surface


def _cache_args(cache: Any, default: tuple[int, int, int] = DEFAULT_CACHE) -> tuple[int, int, int]:
    if cache is None:
        return default
    if isinstance(cache, dict):
        vals = (cache.get("size_bytes"), cache.get("line_bytes", 64), cache.get("ways", 4))
    elif isinstance(cache, tuple | list):
        if len(cache) != 3:
            raise ValueError("cache must be (size_bytes, line_bytes, ways)")
        vals = tuple(cache)
    else:
        try:
            vals = (cache.size_bytes, cache.line_bytes, cache.ways)
        except AttributeError:
            raise ValueError(
                f"cache must be a CacheConfig, a dict or a tuple, got {type(cache).__name__}"
            ) from None
    for v in vals:
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0 or v >= 2**32:
            raise ValueError(f"cache sizes must be non-negative integers, got {vals!r}")
    return int(vals[0]), int(vals[1]), int(vals[2])


def _previous(previous: Any) -> Any:
    if previous is None:
        return None
    if isinstance(previous, RenderResult):
        return previous.multirate_state
    if isinstance(previous, StereoResult):
        return previous.left.multirate_state
    if isinstance(previous, _core.MultirateState):
        return previous
    raise ValueError(f"previous must be a RenderResult or its multirate_state, got {type(previous).__name__}")


def _render_size(camera: Camera, settings: RenderSettings) -> tuple[int, int]:
    s = settings.resolution_scale
    return max(1, round(camera.width * s)), max(1, round(camera.height * s))


def _trace_args(bvh_width: Any, log_rays: Any) -> dict[str, Any]:
    if bvh_width not in (2, 4) or isinstance(bvh_width, bool):
        raise ValueError(
            f"bvh_width must be 4 (the 4-wide BVH) or 2 (the binary reference walk), got {bvh_width!r}"
        )
    if not isinstance(log_rays, bool):
        raise ValueError(f"log_rays must be a bool, got {log_rays!r}")
    return {"bvh_width": int(bvh_width), "log_rays": log_rays}


def _check(scene: Scene, camera: Camera, settings: RenderSettings | None) -> RenderSettings:
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a sim_core.Scene, got {type(scene).__name__}")
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a sim_core.Camera, got {type(camera).__name__}")
    return _check_settings(RenderSettings() if settings is None else settings)


def _result(
    d: dict[str, Any], camera: Camera, settings: RenderSettings, size: tuple[int, int]
) -> RenderResult:
    aovs = {k: d[k] for k in ("depth", "normal", "object_id", "sample_kind")}
    aovs["position"] = d["position"]
    counters = {k: int(v) for k, v in d["counters"].items()}
    rays = TracedRays(**d["rays"]) if "rays" in d else None
    return RenderResult(
        image=upsample_bilinear(d["image"], camera.height, camera.width),
        aovs=aovs,
        counters=counters,
        tile_stats=list(d["tile_stats"]),
        comparator_histogram=np.asarray(d["comparator_histogram"], dtype=np.int64),
        multirate_state=d["multirate_state"],
        settings=settings,
        camera=camera,
        render_resolution=size,
        rays=rays,
    )


def render(
    scene: Scene,
    camera: Camera,
    settings: RenderSettings | None = None,
    threads: int | None = None,
    previous: Any = None,
    cache: Any = None,
    texture_cache: Any = None,
    *,
    bvh_width: int = 4,
    log_rays: bool = False,
) -> RenderResult:
    """Render one frame; multithreaded over tiles with the GIL released.

    previous: the previous frame's RenderResult (or its multirate_state) for multi-rate tiles.
    cache: node/triangle cache of the T&I unit (CacheConfig, dict or (size_bytes, line_bytes, ways));
      None uses DEFAULT_CACHE; size 0 disables it (every fetch goes to DRAM).
    texture_cache: the shading cores' texture cache, same forms (a profile's ``texture_cache``); None uses
      DEFAULT_TEXTURE_CACHE. Only scenes with textures touch it.
    bvh_width: 4 walks the 4-wide BVH (what the energy model prices); 2 the binary BVH, the slow reference
      (the same images but where coplanar duplicates' rounded t differ; node counters in 32-byte nodes).
    log_rays: also return every traced ray (``result.rays``), e.g. to replay them through another tracer.
    """
    trace = _trace_args(bvh_width, log_rays)
    settings = _check(scene, camera, settings)
    w, h = _render_size(camera, settings)
    d = _core.render_frame(
        scene.native,
        camera.frame(),
        camera.vfov,
        w,
        h,
        settings.to_native(),
        _threads(threads),
        _previous(previous),
        *_cache_args(cache),
        *_cache_args(texture_cache, DEFAULT_TEXTURE_CACHE),
        **trace,
    )
    return _result(d, camera, settings, (w, h))


def render_tiled(
    scene: Scene,
    camera: Camera,
    settings: RenderSettings | None = None,
    threads: int | None = None,
    cache: Any = None,
    texture_cache: Any = None,
    *,
    band_pixels: int = 1 << 16,
    progress: Callable[[int, int], None] | None = None,
) -> RenderResult:
    """The frame `render()` gives (same rays, sampling seeds and tile grid: the same image and counters),
    traced in horizontal bands of whole tiles of about `band_pixels` pixels, one native call each.

    Between bands `progress(rows_done, rows_total)` is called on the calling thread (raise from it to
    stop), so a long render (a full-resolution preview) can report progress and be cancelled. The result
    carries no multi-rate history (`multirate_state` is None): it is a still frame.
    """
    settings = _check(scene, camera, settings)
    w, h = _render_size(camera, settings)
    ts = settings.tile_size
    band = ts * max(1, -(-int(band_pixels) // (w * ts)))
    parts: list[RenderResult] = []
    for y0 in range(0, h, band):
        parts.append(render_window(scene, camera, settings, (0, y0, w, min(band, h - y0)), threads, cache,
                                   texture_cache))
        if progress is not None:
            progress(y0 + parts[-1].image.shape[0], h)
    image = np.concatenate([p.image for p in parts], axis=0)
    return RenderResult(
        image=upsample_bilinear(image, camera.height, camera.width),
        aovs={k: np.concatenate([p.aovs[k] for p in parts], axis=0) for k in parts[0].aovs},
        counters={k: sum(p.counters.get(k, 0) for p in parts) for k in parts[0].counters},
        tile_stats=[t for p in parts for t in p.tile_stats],
        comparator_histogram=np.sum([p.comparator_histogram for p in parts], axis=0),
        multirate_state=None,
        settings=settings,
        camera=camera,
        render_resolution=(w, h),
    )


def render_size(camera: Camera, settings: RenderSettings) -> tuple[int, int]:
    """(width, height) actually traced for ``camera`` under ``settings`` (its resolution scale applied)."""
    return _render_size(camera, _check_settings(settings))


def _check_settings(settings: Any) -> RenderSettings:
    if not isinstance(settings, RenderSettings):
        raise ValueError(f"settings must be a sim_core.RenderSettings, got {type(settings).__name__}")
    return settings


def window_apron(settings: RenderSettings, ambient: bool = True) -> int:
    """Pixels beyond each edge of a window that ``render_window`` traces for the resolve pass (0 without
    one): 1 for the pixel filter of a sub-pixel grid (its 1.5 px support reaches 1 px past a pixel), 2
    for the ambient pool of AO (3 with both), and in the adaptive modes the rest of the reference cells
    that hold them (up to ``block - 1`` samples more). ``ambient``: AO rays are traced (``ao_samples`` > 0
    under a world that gives light; True is the bound when the world is not known)."""
    s = _check_settings(settings)
    return int(_core.window_apron_pixels(s.to_native(), bool(ambient and s.ao_samples > 0)))


def render_window(
    scene: Scene,
    camera: Camera,
    settings: RenderSettings,
    window: tuple[int, int, int, int],
    threads: int | None = None,
    cache: Any = None,
    texture_cache: Any = None,
) -> RenderResult:
    """The ``(x, y, width, height)`` window of the frame ``render(scene, camera, settings)`` traces, in
    pixels of the traced (resolution-scaled) frame, traced alone: rays, sampling seeds, ray cones and the
    tile grid are the whole frame's, so the window has the frame's pixels anywhere, in every mode. Its
    tiles are the frame's tiles inside it: a whole tile has the frame's per-tile counters
    (``tile_counters``, caches cold per tile); a tile the window's edge cuts (a window off the tile grid)
    is traced only over its part in the window (adaptively, the reference cells holding it), and its
    ``tile_stats`` rect and counters are that part's.

    The result's ``image`` (and AOVs) are the window's pixels at the traced resolution (not upscaled);
    ``render_resolution`` is the whole traced frame's size; ``tile_stats`` carry frame coordinates;
    ``counters`` are the window's tiles' sums. No multi-rate history (``multirate_state`` None).
    A window that goes through the resolve pass also traces an apron of ``window_apron(settings)`` pixels
    or fewer around itself (what the pixel filter and the ambient pool read, up to the frame's edges):
    real work in no counter, whose rays are ``extra["apron_rays"]``.
    """
    settings = _check(scene, camera, settings)
    w, h = _render_size(camera, settings)
    try:
        x, y, ww, wh = (int(v) for v in window)
    except (TypeError, ValueError):
        raise ValueError(f"window must be (x, y, width, height), got {window!r}") from None
    if ww < 1 or wh < 1 or x < 0 or y < 0 or x + ww > w or y + wh > h:
        raise ValueError(f"window {window!r} is not inside the traced {w}x{h} frame")
    d = _core.render_frame(scene.native, camera.frame(), camera.vfov, ww, wh, settings.to_native(),
                           _threads(threads), None, *_cache_args(cache),
                           *_cache_args(texture_cache, DEFAULT_TEXTURE_CACHE),
                           crop_x=x, crop_y=y, full_width=w, full_height=h)
    return RenderResult(
        image=d["image"],
        aovs={k: d[k] for k in ("depth", "normal", "object_id", "sample_kind", "position")},
        counters={k: int(v) for k, v in d["counters"].items()},
        tile_stats=[{**t, "x0": int(t["x0"]) + x, "y0": int(t["y0"]) + y} for t in d["tile_stats"]],
        comparator_histogram=np.asarray(d["comparator_histogram"], dtype=np.int64),
        multirate_state=None,
        settings=settings,
        camera=camera,
        render_resolution=(w, h),
        extra={"window": (x, y, ww, wh), "apron_rays": int(d["apron_rays"])},
    )


def render_stereo(
    scene: Scene,
    camera: Camera,
    eye_separation: float,
    settings: RenderSettings | None = None,
    threads: int | None = None,
    previous: Any = None,
    cache: Any = None,
    texture_cache: Any = None,
    *,
    bvh_width: int = 4,
    log_rays: bool = False,
) -> StereoResult:
    """Render a stereo pair around `camera` (eyes at -/+ eye_separation / 2 along its right axis).

    The left eye is rendered with `settings`; the right eye reuses reprojected left-eye shading where valid
    and traces the bad pixels (holes from disocclusion or the frame edge, depth mismatches).
    bvh_width and log_rays as for render().
    """
    trace = _trace_args(bvh_width, log_rays)
    settings = _check(scene, camera, settings)
    if (
        isinstance(eye_separation, bool)
        or not isinstance(eye_separation, int | float)
        or not math.isfinite(eye_separation)
        or eye_separation < 0
    ):
        raise ValueError(f"eye_separation must be a finite number >= 0, got {eye_separation!r}")
    left, right = camera.shifted(-eye_separation / 2), camera.shifted(eye_separation / 2)
    w, h = _render_size(camera, settings)
    d = _core.render_stereo(
        scene.native,
        left.frame(),
        right.frame(),
        camera.vfov,
        w,
        h,
        settings.to_native(),
        _threads(threads),
        _previous(previous),
        *_cache_args(cache),
        *_cache_args(texture_cache, DEFAULT_TEXTURE_CACHE),
        **trace,
    )
    return StereoResult(
        left=_result(d["left"], left, settings, (w, h)),
        right=_result(d["right"], right, settings, (w, h)),
        reuse_ratio=float(d["reuse_ratio"]),
        holes=int(d["holes"]),
        silhouettes=int(d["silhouettes"]),
        depth_mismatches=int(d["depth_mismatches"]),
    )
