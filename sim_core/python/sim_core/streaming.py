"""Streaming ray traversal (thesis ch. 3) against per-ray traversal: fetches and bytes per frame.

The thesis' figure of merit is memory traffic per (triangle x pixel x frame): 0.022 B for its streaming
ray caster against 0.52 B for per-ray GPU traversal (Table 3.1). ``compare_traversal`` measures the same
quantity for one batch of rays on our BVH, for per-ray traversal without a cache (the Foley-Sugerman
situation), per-ray traversal behind the hardware profile's per-tile cache (what our tracer models), and
streaming traversal with conditional output streams.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _core

__all__ = ["TraversalComparison", "compare_traversal", "pinhole_rays", "reflection_rays", "traverse"]


def _rays(origins: Any, directions: Any) -> tuple[np.ndarray, np.ndarray]:
    o = np.ascontiguousarray(origins, dtype=np.float32)
    d = np.ascontiguousarray(directions, dtype=np.float32)
    if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
        raise ValueError(f"origins and directions must both be (N, 3), got {o.shape} and {d.shape}")
    if not (np.isfinite(o).all() and np.isfinite(d).all()):
        raise ValueError("rays must be finite")
    if (np.abs(d).sum(axis=1) == 0).any():
        raise ValueError("ray directions must be non-zero")
    return o, d


def pinhole_rays(eye: Any, target: Any, up: Any, vfov: float, width: int, height: int,
                 tile: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Primary rays of a pinhole camera (looks down its -Z, +Y up), one per pixel centre, in tile order
    (tile x tile blocks, row-major) so that consecutive groups of tile*tile rays are the tracer's tiles."""
    if width < 1 or height < 1 or tile < 1 or not (0 < vfov < math.pi):
        raise ValueError("need width, height, tile >= 1 and 0 < vfov < pi")
    eye = np.asarray(eye, dtype=np.float64)
    fwd = np.asarray(target, dtype=np.float64) - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) == 0:
        raise ValueError("up is parallel to the view direction")
    right /= np.linalg.norm(right)
    true_up = np.cross(right, fwd)
    half_h = math.tan(vfov / 2)
    half_w = half_h * width / height
    ys, xs = np.mgrid[0:height, 0:width]
    order = np.lexsort((xs.ravel() % tile, ys.ravel() % tile, xs.ravel() // tile, ys.ravel() // tile))
    px, py = xs.ravel()[order], ys.ravel()[order]
    sx = ((px + 0.5) / width * 2 - 1) * half_w
    sy = (1 - (py + 0.5) / height * 2) * half_h
    d = fwd[None, :] + sx[:, None] * right[None, :] + sy[:, None] * true_up[None, :]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(eye, d.shape)
    return np.ascontiguousarray(o, dtype=np.float32), np.ascontiguousarray(d, dtype=np.float32)


def reflection_rays(positions: Any, triangles: Any, origins: np.ndarray, directions: np.ndarray,
                    t: np.ndarray, prim: np.ndarray, eps: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """Mirror-reflection rays at the hits of (origins, directions): the ray generation the thesis streams
    (its primary visibility comes from z-buffering). Rays that missed produce no reflection ray."""
    p = np.asarray(positions, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64)
    hit = prim >= 0
    o = origins[hit].astype(np.float64)
    d = directions[hit].astype(np.float64)
    x = o + d * t[hit, None]
    v = tri[prim[hit]]
    n = np.cross(p[v[:, 1]] - p[v[:, 0]], p[v[:, 2]] - p[v[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    n *= -np.sign(np.sum(n * d, axis=1, keepdims=True) + 1e-30)  # face the incoming ray
    r = d - 2 * np.sum(d * n, axis=1, keepdims=True) * n
    scale = max(1.0, float(np.abs(p).max()))
    return (np.ascontiguousarray(x + n * eps * scale, dtype=np.float32),
            np.ascontiguousarray(r, dtype=np.float32))


def traverse(scene: Any, origins: Any, directions: Any, mode: str = "streaming", cache: Any = None,
             group_size: int = 0) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Closest hits (t, original prim id) of a ray batch and the traversal's traffic counters."""
    o, d = _rays(origins, directions)
    native = getattr(scene, "native", scene)
    kw: dict[str, Any] = {"group_size": int(group_size)}
    if cache is not None:
        kw.update(cache_size=int(cache.size_bytes), cache_line=int(cache.line_bytes),
                  cache_ways=int(cache.ways))
    if mode not in ("streaming", "per_ray"):
        raise ValueError(f"mode must be 'streaming' or 'per_ray', got {mode!r}")
    if mode == "streaming" and cache is not None:
        raise ValueError("streaming traversal fetches each node once per stream; it takes no cache")
    return _core.traverse_rays(native, o, d, mode, **kw)


@dataclass(frozen=True)
class TraversalComparison:
    """Traffic of one ray batch under three traversal schemes, normalised as in thesis Table 3.1."""

    triangles: int
    pixels: int
    rays: int
    per_ray: dict[str, int]  # no cache: every node/triangle fetch is memory traffic
    per_ray_cached: dict[str, int] | None  # behind the per-tile cache model
    streaming: dict[str, int]
    same_hits: bool  # streaming found exactly the per-ray closest hits

    def bytes_per_tri_pixel(self, traffic: dict[str, int], include_streams: bool = False) -> float:
        b = traffic["scene_dram_bytes"] + (traffic["stream_bytes"] if include_streams else 0)
        return b / (self.triangles * self.pixels)

    @property
    def avg_interior_stream(self) -> float:
        s = self.streaming
        return s["interior_stream_rays"] / max(s["interior_streams"], 1)

    @property
    def avg_leaf_stream(self) -> float:
        s = self.streaming
        return s["leaf_stream_rays"] / max(s["leaf_streams"], 1)


def compare_traversal(scene: Any, origins: Any, directions: Any, pixels: int, cache: Any = None,
                      group_size: int = 256) -> TraversalComparison:
    """Trace one batch per-ray (without and, if ``cache`` is given, with the per-tile cache) and streamed."""
    t0, p0, per_ray = traverse(scene, origins, directions, "per_ray")
    cached = None
    if cache is not None:
        _, _, cached = traverse(scene, origins, directions, "per_ray", cache=cache, group_size=group_size)
    t1, p1, stream = traverse(scene, origins, directions, "streaming")
    same = bool(np.array_equal(t0, t1) and np.array_equal(p0[t0 != np.inf], p1[t1 != np.inf]))
    stats = getattr(scene, "stats", {}) or {}
    tris = int(stats.get("triangles", 0))
    if tris <= 0:
        raise ValueError("cannot tell the scene's triangle count")
    return TraversalComparison(triangles=tris, pixels=int(pixels), rays=len(t0), per_ray=per_ray,
                               per_ray_cached=cached, streaming=stream, same_hits=same)
