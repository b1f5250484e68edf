"""Preview frames in this process with the bundled core: the scene exported from Blender, rendered band by
band (`sim_core.render_tiled`: progress, cancel, memory of one band for the traversal) at any resolution
the machine can hold, and priced on a hardware profile. Pure (no bpy): the operator reads the scene and
camera and writes the image. The native core (sim_core, and the service modules that import it) is
imported inside the functions that use it, "lazy" below: the add-on registers without loading it."""

from __future__ import annotations

import hashlib
import math
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: Bytes per pixel a preview holds at once: the traced image and its AOVs (depth, normal, position,
#: object id, sample kind: 45 B), the image handed to Blender (RGBA float, 16 B) and the upscaled copy.
BYTES_PER_PIXEL = 80
SCENES_KEPT = 2


class PreviewCancelled(Exception):
    """The user cancelled the preview."""


@dataclass(frozen=True)
class Preview:
    image: np.ndarray  # (height, width, 3) float32 linear RGB, row 0 at the top
    power_w: float
    frame_time_s: float
    energy: dict[str, Any]
    counters: dict[str, int]
    render_s: float


_scenes: OrderedDict[str, Any] = OrderedDict()


def load_scene(scene_path: str | Path) -> Any:
    """The scene of a scene file (or .glb), loaded once per content (previews of an unchanged scene skip
    the BVH build)."""
    from service.evaluation import read_scene  # lazy: loads the native core (above)

    data = Path(scene_path).read_bytes()
    key = hashlib.sha256(data).hexdigest()
    scene = _scenes.get(key)
    if scene is None:
        try:
            scene = read_scene(scene_path)
        except (ValueError, FileNotFoundError) as exc:
            raise ValueError(f"the simulator cannot load this scene: {exc}") from exc
        _scenes[key] = scene
        while len(_scenes) > SCENES_KEPT:
            _scenes.popitem(last=False)
    _scenes.move_to_end(key)
    return scene


def available_memory() -> int | None:
    """Bytes of memory available now (Linux: MemAvailable; elsewhere unknown: None)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_size(width: int, height: int, available: int | None = None) -> None:
    """A preview this machine can hold, else ValueError saying how much it needs and has."""
    if not all(isinstance(v, int) and 4 <= v <= 16384 for v in (width, height)):
        raise ValueError(f"preview size must be 4..16384 pixels per side, got {width}x{height}")
    need = width * height * BYTES_PER_PIXEL
    have = available_memory() if available is None else available
    if have is not None and need > 0.8 * have:
        raise ValueError(f"a {width}x{height} preview needs about {need / 2**30:.1f} GiB of memory and "
                         f"{have / 2**30:.1f} GiB are available: lower the preview scale")


def settings_indices(values: Mapping[str, Any] | None) -> tuple[Any, tuple[int, ...]]:
    """The space holding `{parameter: value}` (what a store lookup returns; the default one when it can,
    as the service's render route) and its indices; parameters left out stay at maximum quality."""
    from service.params import space_holding  # lazy: loads the native core (above)

    space = space_holding(values)
    return space, space.indices_of(values)


def encode(image: np.ndarray, fmt: str) -> bytes:
    """Linear float RGB as PNG (8-bit sRGB) or EXR (32-bit float) bytes, as POST /render encodes them."""
    from sim_core.image import encode_exr, encode_png  # lazy: the native core (above)

    if fmt not in ("png", "exr"):
        raise ValueError(f"format must be png or exr, got {fmt!r}")
    return encode_png(image) if fmt == "png" else encode_exr(image)


def render(scene: Any, matrix_world: Sequence[Sequence[float]], vfov: float, width: int, height: int, *,
           settings: Mapping[str, Any] | None = None, profile: str = "mobile", fps: float = 30.0,
           threads: int | None = None, progress: Callable[[float], None] | None = None,
           should_cancel: Callable[[], bool] | None = None) -> Preview:
    """Render and price one frame. `progress(fraction)` after each band; `should_cancel()` is asked after
    each band (raises PreviewCancelled)."""
    import sim_core  # lazy: the native core (above)

    check_size(width, height)
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, got {fps!r}")
    m = np.array(matrix_world, dtype=np.float64)
    m[3] = (0.0, 0.0, 0.0, 1.0)
    camera = sim_core.Camera.from_blender(m, float(vfov), int(width), int(height))
    space, indices = settings_indices(settings)
    rs = space.to_settings(indices)
    prof = sim_core.load_profile(profile)

    def on_band(done: int, total: int) -> None:
        if should_cancel is not None and should_cancel():
            raise PreviewCancelled
        if progress is not None:
            progress(done / total)

    t0 = time.perf_counter()
    result = sim_core.render_tiled(scene, camera, rs, threads=threads, cache=prof.cache,
                                   texture_cache=prof.texture_cache, progress=on_band)
    seconds = time.perf_counter() - t0
    report = sim_core.price(result, prof, float(fps), scene=scene)
    energy = {"power_w": float(report.power_w), "frame_time_s": float(report.frame_time_s),
              "max_fps": float(report.max_fps), "deadline_met": bool(report.deadline_met),
              "bottleneck": str(report.bottleneck), "profile": profile, "fps": float(fps),
              "achieved_fps": float(report.achieved_fps),  # the rate power_w is drawn at
              "energy_j": {k: float(v) for k, v in report.energy_j.items()}}
    counters = {k: int(v) for k, v in result.counters.items()}
    return Preview(np.asarray(result.image, dtype=np.float32), float(report.power_w),
                   float(report.frame_time_s), energy, counters, seconds)

