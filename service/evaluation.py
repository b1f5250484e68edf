"""Error and power of one settings vector at one camera (power-budget paper, Eq. 1 and sec. 5.1.1).

``error = 1 - SSIM(reference, image)`` where the reference is the maximum-quality render of the same
camera; ``power`` is what the modelled GPU draws at the frame rate it reaches when asked for the target
frame rate (``sim_core.sustained_power``: the target when the frame meets its deadline, else its own
lower rate; never above the full-speed power), ``frame_time_s`` the modelled frame time. Both images go
through one fixed display transform before SSIM: linear RGB clamped to [0, 1], then the sRGB transfer
curve (so the error is measured on what a display shows, and highlights above 1 do not dominate). A
render smaller than the reference (resolution scale) is upsampled bilinearly to the reference size first.

Evaluations run at a small resolution, but the power a store predicts is for the path's real
resolution: static power stays, dynamic energy and frame time are scaled by the pixel-count ratio
(``target_pixels``; the energy model's dynamic energy grows linearly with pixels, see its tests), and
the power is drawn at the frame rate that scaled frame time reaches. At a few hundred pixels the static
power would otherwise hide every difference between settings.

:class:`Evaluator` is the driver side: it answers batches of (camera, settings) from the persistent
cache and sends only the misses, as one batch, to an executor; workers keep their scene and each
camera's reference render, so a reference is rendered once per worker and camera (once per process
however many threads evaluate at that camera at once), and maximum quality itself is priced from it.
"""

from __future__ import annotations

import hashlib
import math
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from sim_core.image import linear_to_srgb, upsample_bilinear
from sim_core.loaders.scene_file import SUFFIX, is_scene_file

import sim_core
from service.eval_cache import CacheKey, EvalCache, Evaluation
from service.executors import Executor, InProcessExecutor
from service.lru import LRUCache
from service.metrics import flip, ssim
from service.options import METRICS
from service.params import Indices, ParameterSpace
from service.store.camera import check_fov

#: Bumped whenever the pipeline that turns renders into errors or power changes (part of every cache
#: key). v2: power at the frame rate reached (it was P_static + E * target fps even for frames that
#: miss their deadline).
PIPELINE_VERSION = "v2"

__all__ = ["METRICS", "CameraSpec", "Evaluation", "Evaluator", "Reference", "SceneHandle", "evaluate",
           "image_error", "reference"]


@dataclass(frozen=True)
class CameraSpec:
    """A pinhole camera for evaluation: eye, forward and up (world, Z up), vertical fov, resolution."""

    eye: tuple[float, float, float]
    forward: tuple[float, float, float]
    up: tuple[float, float, float]
    vfov: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("eye", "forward", "up"):
            v = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(f"camera {name} must be 3 finite numbers")
            object.__setattr__(self, name, tuple(float(c) for c in v))
        if np.linalg.norm(self.forward) < 1e-12:
            raise ValueError("camera forward must be non-zero")
        if np.linalg.norm(np.cross(self.forward, self.up)) < 1e-9:
            raise ValueError("camera up must not be parallel to forward")
        check_fov(self.vfov, "vfov")  # the limits every layer shares
        if int(self.width) < 8 or int(self.height) < 8:
            raise ValueError("evaluation images need at least 8x8 pixels")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        f = ",".join(f"{c:.6f}" for c in (*self.eye, *self.forward, *self.up, self.vfov))
        object.__setattr__(self, "_key", f"{f}|{self.width}x{self.height}")

    @classmethod
    def from_matrix(cls, matrix_world: Any, vfov: float, width: int, height: int) -> CameraSpec:
        """The camera of a Blender camera world matrix (it looks down its local -Z, up its local +Y), as
        path frames, add-on payloads and REST bodies carry it."""
        m = np.asarray(matrix_world, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError("camera matrix_world must be 4x4")
        return cls(tuple(m[:3, 3]), tuple(-m[:3, 2]), tuple(m[:3, 1]), vfov, width, height)

    def key(self) -> str:
        """Stable text key (values rounded to 1e-6) used by caches."""
        return self._key  # type: ignore[attr-defined,no-any-return]

    def to_camera(self) -> Any:
        """The tracer's camera (built once per process and key)."""
        cam = _CAMERAS.get(self._key)  # type: ignore[attr-defined]
        if cam is None:
            target = tuple(e + f for e, f in zip(self.eye, self.forward, strict=True))
            cam = sim_core.Camera.look_at(self.eye, target, self.up, self.vfov, self.width, self.height)
            _CAMERAS.put(self._key, cam)  # type: ignore[attr-defined]
        return cam


_CAMERAS: LRUCache[str, Any] = LRUCache(4096)


class SceneHandle:
    """A scene that can travel to worker processes: its content hash plus the file it was loaded from.

    In the process that made it the handle holds the loaded scene; pickled, it carries the path (and
    the file bytes when ``ship_bytes``, for workers without a shared file system), or a picklable
    ``loader`` callable that rebuilds the scene, and loads the scene once per worker process."""

    def __init__(self, scene: Any = None, path: str | Path | None = None, *,
                 ship_bytes: bool = False, loader: Any = None, self_contained: bool = False) -> None:
        if scene is None and path is None and loader is None:
            raise ValueError("a scene handle needs a scene, a path or a loader")
        self.loader = loader
        self.self_contained = self_contained  # an upload: workers read nothing but the file itself
        if scene is None and path is None:
            scene = loader()
        if path is None and scene is not None:
            src = str(getattr(scene, "source", "") or "")
            path = src if src and Path(src).is_file() else None  # loaded from a file: workers reload it
        self.path = None if path is None else str(path)
        self._data: bytes | None = Path(path).read_bytes() if (ship_bytes and path is not None) else None
        if scene is None:
            scene = _load_scene(self.path, None, self.self_contained)  # type: ignore[arg-type]
        self.content_hash = str(scene.content_hash)
        _SCENES.put(self.content_hash, scene)
        self._scene = scene

    def get(self) -> Any:
        if self._scene is None:
            with _LOCK:
                s = _SCENES.get(self.content_hash)
                if s is None:
                    if self.path is not None:
                        s = _load_scene(self.path, self._data, self.self_contained)
                    elif self.loader is not None:
                        s = self.loader()
                    else:
                        raise RuntimeError("this scene has no file or loader for a worker process")
                    if str(s.content_hash) != self.content_hash:
                        raise RuntimeError("the worker loaded a different scene (content hash differs)")
                    _SCENES.put(self.content_hash, s)
            self._scene = s
        return self._scene

    def __getstate__(self) -> dict[str, Any]:
        if self.path is None and self.loader is None:
            raise RuntimeError("a scene without a source file or loader can only be evaluated in-process")
        return {"path": self.path, "data": self._data, "content_hash": self.content_hash,
                "loader": self.loader, "self_contained": self.self_contained}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.path = state["path"]
        self._data = state["data"]
        self.loader = state["loader"]
        self.content_hash = state["content_hash"]
        self.self_contained = state["self_contained"]
        self._scene = _SCENES.get(self.content_hash)


def _load_scene(path: str, data: bytes | None, self_contained: bool) -> Any:
    """Load a scene file; a worker without the file loads the shipped bytes from a private folder that
    is removed as soon as the scene is in memory (only the file travels, so it must be self-contained)."""
    p = Path(path)
    if data is not None and not p.exists():
        with tempfile.TemporaryDirectory(prefix="render-budget-scene-") as tmp:
            copy = Path(tmp) / p.name
            copy.write_bytes(data)
            return read_scene(copy, self_contained=True)
    return read_scene(p, self_contained=self_contained)


def read_scene(path: str | Path, *, self_contained: bool = False) -> Any:
    """A ``sim_core.Scene`` from a file: a render-budget scene file (known by its content, whatever its
    name: what the add-on sends), ``.glb``/``.gltf`` or ``.obj``. ``self_contained``: a glTF may refer to
    nothing outside itself (uploads; see ``sim_core.loaders.gltf.load_gltf``)."""
    p = Path(path)
    if is_scene_file(p):
        return sim_core.Scene.from_scene_file(p)
    if p.suffix.lower() in (".glb", ".gltf"):
        return sim_core.Scene.from_gltf(str(p), self_contained=self_contained)
    if p.suffix.lower() == ".obj":
        return sim_core.Scene.from_obj(str(p))
    raise ValueError(f"unsupported scene file {p.name!r} (use a {SUFFIX} scene file, .glb, .gltf or .obj)")


def load_scene(path: str | Path, *, ship_bytes: bool = False) -> SceneHandle:
    """Load a scene file into a handle usable by every executor."""
    return SceneHandle(path=path, ship_bytes=ship_bytes)


@dataclass(frozen=True)
class Reference:
    """A camera's maximum-quality render as evaluations keep it: the image every error at that camera
    is measured against, and what the energy model prices (counters, comparator histogram, settings),
    so that evaluating maximum quality itself prices this render instead of rendering the same image
    again."""

    image: np.ndarray
    activity: SimpleNamespace
    display: np.ndarray  # the image through the display transform (what SSIM compares), made once

    @property
    def nbytes(self) -> int:
        return int(self.image.nbytes + self.display.nbytes)


# worker-process state: the few most recent scenes by content hash (a long-lived worker sees many jobs),
# profiles by name, references (64x36 ones are ~27 KB: a whole lockstep batch of samples fits; 320x180
# ones ~2 MB with their display transform: a path's evaluated frames fit under the byte cap)
_LOCK = threading.Lock()  # one scene load at a time
_SCENES: LRUCache[str, Any] = LRUCache(8)
_PROFILES: dict[str, Any] = {}
REFERENCE_CACHE_BYTES = 512 * 1024**2
_REFS: LRUCache[tuple[str, ...], Reference] = LRUCache(512, weigh=lambda r: r.nbytes,
                                                       max_weight=REFERENCE_CACHE_BYTES)
_REF_LOCKS: dict[tuple[str, ...], threading.Lock] = {}  # references being rendered, by key
_REF_LOCKS_GUARD = threading.Lock()


def _profile(name: str) -> Any:
    p = _PROFILES.get(name)
    if p is None:
        p = sim_core.load_profile(name)
        _PROFILES[name] = p
    return p


def _render(scene: Any, camera: CameraSpec, settings: Any, threads: int | None) -> Any:
    return sim_core.render(scene, camera.to_camera(), settings, threads=threads)


def _image(result: Any) -> np.ndarray:
    img = np.asarray(result.image)
    if img.ndim != 3 or img.shape[2] != 3 or not np.all(np.isfinite(img)):
        raise ValueError("render returned a non-finite or malformed image")
    return img


def image_error(metric: str, reference: np.ndarray, image: np.ndarray) -> float:
    """The error of ``image`` against the maximum-quality ``reference`` (linear RGB; a smaller image is
    upsampled to the reference's size) by ``metric`` on display values, in [0, 1]: what a store's
    errors mean, for anyone who measures one (the render engine's Measure Error)."""
    return _display_error(metric, linear_to_srgb(reference), image)


def _display_error(metric: str, ref: np.ndarray, image: np.ndarray) -> float:
    """:func:`image_error` against a reference already through the display transform."""
    img = linear_to_srgb(upsample_bilinear(image, ref.shape[0], ref.shape[1]))
    if metric == "ssim":
        e = 1.0 - ssim(ref, img, data_range=1.0)
    elif metric == "ssim_gaussian":
        e = 1.0 - ssim(ref, img, data_range=1.0, gaussian_weights=True)
    elif metric == "flip":
        e = flip(ref, img)
    else:
        raise ValueError(f"unknown metric {metric!r} (choose from {METRICS})")
    return float(min(max(e, 0.0), 1.0))


def _price(result: Any, profile: str, fps: float, pixel_ratio: float = 1.0
           ) -> tuple[float, float, dict[str, float]]:
    """Power (W) and frame time at ``pixel_ratio`` times the rendered pixel count (dynamic energy and
    frame time scale with the pixels; the power is drawn at the frame rate that frame time reaches), and
    the breakdown (energy per block at the rendered size, the frame rate reached at the scaled size)."""
    prof = _profile(profile)
    rep = sim_core.price(result, prof, fps)
    frame_time = float(rep.frame_time_s) * pixel_ratio
    power, reached = sim_core.sustained_power(prof.static_power_w, float(rep.dynamic_energy_j) * pixel_ratio,
                                              frame_time, fps)
    breakdown = {f"energy_j.{k}": float(v) for k, v in dict(rep.energy_j).items()}
    breakdown["rays_total"] = float(getattr(rep, "rays_total", 0))
    breakdown["pixel_ratio"] = float(pixel_ratio)
    breakdown["fps"] = reached
    return power, frame_time, breakdown


def reference(scene: Any, scene_hash: str, camera: CameraSpec, space: ParameterSpace,
              indices: Indices | None = None, threads: int | None = None) -> Reference:
    """The reference render of ``indices`` (default: the space's maximum quality) at ``camera``, rendered
    once per process: concurrent evaluations at one camera (the service answers requests on several
    threads) wait for one render instead of each rendering the same image."""
    idx = space.max_quality_indices() if indices is None else tuple(int(i) for i in indices)
    key = (scene_hash, camera.key(), repr(sorted(space.fields_of(idx).items())))
    ref = _REFS.get(key)
    if ref is not None:
        return ref
    with _REF_LOCKS_GUARD:
        lock = _REF_LOCKS.setdefault(key, threading.Lock())
    try:
        with lock:
            ref = _REFS.get(key)
            if ref is None:
                result = _render(scene, camera, space.to_settings(idx), threads)
                image = _image(result)
                ref = Reference(image, SimpleNamespace(
                    counters=dict(result.counters), comparator_histogram=result.comparator_histogram,
                    settings=result.settings), linear_to_srgb(image))
                _REFS.put(key, ref)
    finally:
        with _REF_LOCKS_GUARD:
            if _REF_LOCKS.get(key) is lock:
                del _REF_LOCKS[key]
    return ref


def evaluate(scene: Any, camera: CameraSpec, indices: Sequence[int], space: ParameterSpace, *,
             profile: str = "mobile", fps: float = 30.0, metric: str = "ssim", threads: int | None = None,
             reference_indices: Indices | None = None, target_pixels: int | None = None) -> Evaluation:
    """Render ``indices`` at ``camera``, compare with the reference (the render of ``reference_indices``,
    default the space's maximum quality), price the frame (power and frame time for ``target_pixels``
    pixels when given, else for the camera's own). The reference settings themselves are priced from the
    reference render: error 0, no second render."""
    if isinstance(scene, SceneHandle):
        handle_hash, scene = scene.content_hash, scene.get()
    else:
        handle_hash = str(scene.content_hash)
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r} (choose from {METRICS})")
    idx = tuple(int(i) for i in indices)
    space.validate(idx)
    ref_idx = space.max_quality_indices() if reference_indices is None else tuple(
        int(i) for i in reference_indices)
    space.validate(ref_idx)
    ref = reference(scene, handle_hash, camera, space, ref_idx, threads)
    if idx == ref_idx:
        activity, err = ref.activity, 0.0
    else:
        activity = _render(scene, camera, space.to_settings(idx), threads)
        err = _display_error(metric, ref.display, _image(activity))
    ratio = 1.0 if target_pixels is None else float(target_pixels) / (camera.width * camera.height)
    power, frame_time, breakdown = _price(activity, profile, fps, ratio)
    return Evaluation(err, power, frame_time, breakdown)


@dataclass(frozen=True)
class EvalContext:
    """What every task of a batch shares (sent once per worker and batch)."""

    scene: SceneHandle
    space: ParameterSpace
    profile: str
    fps: float
    metric: str
    threads: int | None
    target_pixels: int | None = None


def _eval_task(ctx: EvalContext, item: tuple[CameraSpec, Indices]) -> Evaluation:
    camera, idx = item
    threads = ctx.threads
    if threads is None and camera.width * camera.height <= 64 * 64:
        threads = 1  # tiny images: spinning up the tracer's thread pool costs more than it saves
    return evaluate(ctx.scene, camera, idx, ctx.space, profile=ctx.profile, fps=ctx.fps, metric=ctx.metric,
                    threads=threads, target_pixels=ctx.target_pixels)


def space_fingerprint(space: ParameterSpace) -> str:
    """Short hash of what packed settings mean (parameters and fields), for cache keys."""
    text = repr([(p.name, p.values, [sorted(f.items()) for f in p.fields]) for p in space.parameters])
    return hashlib.sha256(text.encode()).hexdigest()[:12]


class Evaluator:
    """Batches of (camera, settings) -> evaluations, through the cache and then the executor."""

    def __init__(self, scene: SceneHandle | Any, space: ParameterSpace, *, cache: EvalCache,
                 executor: Executor | None = None, profile: str = "mobile", fps: float = 30.0,
                 metric: str = "ssim", threads: int | None = None, target_pixels: int | None = None) -> None:
        if metric not in METRICS:
            raise ValueError(f"unknown metric {metric!r} (choose from {METRICS})")
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError("fps must be positive")
        self.scene = scene if isinstance(scene, SceneHandle) else SceneHandle(scene)
        self.space = space
        self.cache = cache
        self.executor = executor or InProcessExecutor()
        if target_pixels is not None and target_pixels < 1:
            raise ValueError("target_pixels must be positive")
        self.ctx = EvalContext(self.scene, space, profile, float(fps), metric, threads, target_pixels)
        px = "own" if target_pixels is None else str(int(target_pixels))
        self.metric_key = f"{metric}:{PIPELINE_VERSION}:{space_fingerprint(space)}:px={px}"
        # the profile's figures, not just its name: an edited or upgraded profile is priced afresh
        self.profile_key = f"{profile}@{_profile(profile).fingerprint}"
        self.evaluations = 0  # renders actually done
        self.cache_hits = 0
        self.render_time_s = 0.0

    @property
    def fps(self) -> float:
        """The target frame rate power is priced at."""
        return self.ctx.fps

    def _key(self, camera: CameraSpec) -> CacheKey:
        return CacheKey(self.scene.content_hash, camera.key(), self.metric_key, self.profile_key,
                        camera.width, camera.height, self.ctx.fps)

    def evaluate(self, requests: Sequence[tuple[CameraSpec, Sequence[int]]]) -> list[Evaluation]:
        """Evaluations in request order; cached ones are not rendered again."""
        reqs = [(cam, tuple(int(i) for i in idx)) for cam, idx in requests]
        packs = {}
        for _, idx in reqs:
            if idx not in packs:
                packs[idx] = self.space.pack(idx)  # validates once per distinct setting
        by_cam: dict[str, tuple[CameraSpec, dict[int, Indices]]] = {}
        for cam, idx in reqs:
            by_cam.setdefault(cam.key(), (cam, {}))[1][packs[idx]] = idx
        found: dict[tuple[str, int], Evaluation] = {}
        todo: list[tuple[CameraSpec, Indices]] = []
        for ck, (cam, cam_packs) in by_cam.items():
            hit = self.cache.get_many(self._key(cam), list(cam_packs))
            self.cache_hits += len(hit)
            for p, ev in hit.items():
                found[(ck, p)] = ev
            todo.extend((cam, cam_packs[p]) for p in cam_packs if p not in hit)
        if todo:
            t0 = time.perf_counter()
            results = self.executor.map(_eval_task, self.ctx, todo)
            self.render_time_s += time.perf_counter() - t0
            self.evaluations += len(todo)
            grouped: dict[str, list[tuple[int, Evaluation]]] = {}
            for (cam, idx), ev in zip(todo, results, strict=True):
                p = packs[idx]
                found[(cam.key(), p)] = ev
                grouped.setdefault(cam.key(), []).append((p, ev))
            for ck, items in grouped.items():
                self.cache.put_many(self._key(by_cam[ck][0]), items)
        return [found[(cam.key(), packs[idx])] for cam, idx in reqs]
