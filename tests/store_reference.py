"""The store lookup as it was before the fast one (commit f99fe45's ``service/pareto_store.py``, copied
but for names; the pieces that moved unchanged into ``service.store.camera`` are imported from there):
the slow reference the property tests compare ``ParetoStore.lookup`` with. It reads only a store's
public fields.

Extended deliberately once since: the frame-rate target (store format 4). Where a frontier knows its
frame times, the budget search runs over the points whose frame time fits in the store's frame period
1 / fps (all points when none does), and the answer adds the chosen point's frame time, the frame rate it
reaches (fps, or 1 / frame time when it misses) and whether it meets the target (None, None, None for
frontiers without frame times)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from service.store.camera import _look_floats, frustum_rays, vec3

_SIGNED_TO_VIEW = (0, 2, 4, 1, 3, 5)


def camera_rotation(direction: Any = None, matrix: Any = None, up: Any = None) -> np.ndarray:
    """The old rotation: numpy for matrices; a view direction's rotation moved unchanged into
    ``service.store.camera`` (``_look_floats``), so it is taken from there."""
    if (direction is None) == (matrix is None):
        raise ValueError("give exactly one of direction or matrix")
    if matrix is None:
        return np.array(_look_floats(direction, up)).reshape(3, 3)
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape not in ((4, 4), (3, 3)) or not np.all(np.isfinite(m)):
        raise ValueError("matrix must be a finite 4x4 or 3x3 array")
    r = m[:3, :3]
    big = np.abs(r).max(axis=0)
    if np.any(big == 0):
        raise ValueError("matrix has a degenerate rotation")
    r = r / big
    norms = np.linalg.norm(r, axis=0)
    if np.any(norms < 1e-12) or not np.all(np.isfinite(r)):
        raise ValueError("matrix has a degenerate rotation")
    return r / norms


class ReferenceLookup:
    """The old ``ParetoStore`` lookup over a store's fields (its own frustum cache, as each old store
    kept one)."""

    def __init__(self, store: Any) -> None:
        self.s = store
        key = {tuple(int(c) for c in xyz): i for i, xyz in enumerate(store.corner_coords)}
        side = 1 << store.lattice_depth
        self._leaf_corners: dict[int, np.ndarray] = {}
        stack = [(0, 0, 0, 0, side)]
        while stack:
            node, x, y, z, s = stack.pop()
            c = int(store.children[node])
            if c == -1:
                self._leaf_corners[node] = np.asarray([
                    key[(x + s * (k & 1), y + s * ((k >> 1) & 1), z + s * ((k >> 2) & 1))] for k in range(8)])
            else:
                h = s // 2
                for k in range(8):
                    stack.append((c + k, x + h * (k & 1), y + h * ((k >> 1) & 1), z + h * ((k >> 2) & 1), h))
        self._frustum_cache: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}
        cell = store.root_size / side
        self._lo = tuple(float(c) for c in store.root_min)
        self._hi = tuple(float(c) + store.root_size for c in store.root_min)
        self._lattice_scale = side / store.root_size
        self._children_list = [int(c) for c in store.children]
        self._leaf_corner_pos = {
            leaf: [(int(c), tuple(float(v) for v in store.root_min + store.corner_coords[c] * cell))
                   for c in ids] for leaf, ids in self._leaf_corners.items()}

    def find_leaf(self, position: Any) -> tuple[int, np.ndarray, bool]:
        p = vec3(position, "position")
        lo = self._lo
        hi = self._hi
        q = tuple(min(max(p[i], lo[i]), hi[i]) for i in range(3))
        clamped = q != p
        k_scale = self._lattice_scale
        u = [(q[i] - lo[i]) * k_scale for i in range(3)]
        node = 0
        x = y = z = 0
        s = 1 << self.s.lattice_depth
        children = self._children_list
        while children[node] != -1:
            h = s // 2
            k = int(u[0] >= x + h) | (int(u[1] >= y + h) << 1) | (int(u[2] >= z + h) << 2)
            x += h * (k & 1)
            y += h * ((k >> 1) & 1)
            z += h * ((k >> 2) & 1)
            s = h
            node = children[node] + k
        return node, np.asarray(q), clamped

    def _frustum_rays(self, vfov: float, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        key = (round(vfov, 6), round(aspect, 6))
        rays = self._frustum_cache.get(key)
        if rays is None:
            rays = frustum_rays(vfov, aspect)  # moved unchanged into service.store.camera
            if len(self._frustum_cache) > 64:
                self._frustum_cache.clear()
            self._frustum_cache[key] = rays
        return rays

    def choose_view(self, rotation: np.ndarray, vfov: float, aspect: float) -> int:
        rays_t, weights = self._frustum_rays(vfov, aspect)
        d = np.asarray(rotation) @ rays_t
        face = np.concatenate((d, -d)).argmax(axis=0)
        return _SIGNED_TO_VIEW[int(np.bincount(face, weights=weights, minlength=6).argmax())]

    def _locate(self, position: Any, rotation: np.ndarray, vfov: float, aspect: float
                ) -> tuple[int, int, int, bool]:
        leaf, q, clamped = self.find_leaf(position)
        qx, qy, qz = float(q[0]), float(q[1]), float(q[2])
        best = math.inf
        corner = -1
        for c, (cx, cy, cz) in self._leaf_corner_pos[leaf]:
            dd = (cx - qx) ** 2 + (cy - qy) ** 2 + (cz - qz) ** 2
            if dd < best:
                best, corner = dd, c
        return leaf, corner, self.choose_view(rotation, vfov, aspect), clamped

    def locate(self, position: Any, direction: Any = None, matrix: Any = None, fov: float | None = None,
               aspect: float | None = None, up: Any = None) -> tuple[int, int]:
        rot = camera_rotation(direction, matrix, up)
        vf = self.s.vfov if fov is None else float(fov)
        asp = self.s.aspect if aspect is None else float(aspect)
        _, corner, view, _ = self._locate(position, rot, vf, asp)
        return corner, view

    def lookup(self, position: Any, direction: Any = None, matrix: Any = None, fov: float | None = None,
               power_budget: float | None = None, error_budget: float | None = None,
               aspect: float | None = None, up: Any = None) -> tuple:
        """(indices, packed, settings, power_w, error, clamped, infeasible, corner, view, leaf,
        frame_time_s, fps, meets_fps)."""
        if (power_budget is None) == (error_budget is None):
            raise ValueError("give exactly one of power_budget or error_budget")
        budget = float(power_budget if power_budget is not None else error_budget)  # type: ignore[arg-type]
        if not math.isfinite(budget):
            raise ValueError("budget must be finite")
        rot = camera_rotation(direction, matrix, up)
        vf = self.s.vfov if fov is None else float(fov)
        if not (math.isfinite(vf) and 0 < vf < math.pi):
            raise ValueError(f"fov must be in (0, pi) radians, got {fov!r}")
        asp = self.s.aspect if aspect is None else float(aspect)
        if not (math.isfinite(asp) and asp > 0):
            raise ValueError("aspect must be positive")
        leaf, corner, view, clamped = self._locate(position, rot, vf, asp)
        fr = self.s.frontiers[int(self.s.corner_views[corner, view])]
        period = 1.0 / self.s.fps
        keep = np.arange(len(fr))
        if fr.frame_time_s is not None and np.any(fr.frame_time_s <= period):
            keep = np.flatnonzero(fr.frame_time_s <= period)  # settings that keep up with the target
        power_w, error = fr.power_w[keep], fr.error[keep]
        if power_budget is not None:
            i = int(np.searchsorted(power_w, budget, side="right")) - 1
            i, infeasible = (0, True) if i < 0 else (i, False)
        else:
            i = int(np.searchsorted(-error, -budget, side="left"))
            i, infeasible = (len(keep) - 1, True) if i >= len(keep) else (i, False)
        i = int(keep[i])
        packed = int(fr.packed[i])
        indices = tuple((packed >> (4 * k)) & 15 for k in range(len(self.s.parameters)))
        settings = {p.name: p.values[j] for p, j in zip(self.s.parameters, indices, strict=True)}
        timing: tuple = (None, None, None)
        if fr.frame_time_s is not None:
            t = float(fr.frame_time_s[i])
            timing = (t, self.s.fps if t <= period else 1.0 / t, t <= period)
        return (indices, packed, settings, float(fr.power_w[i]), float(fr.error[i]), clamped, infeasible,
                corner, view, leaf, *timing)
