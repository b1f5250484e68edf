"""The runtime lookup: a camera pose and a budget -> the settings a store holds for it.

The work per query is a descent of a few octree levels to the leaf holding the camera, the nearest of
the leaf's eight corners, the view-cube face that receives most of the camera's frustum
(:func:`service.store.camera.frustum_face`) and a binary search on that (corner, face)'s frontier.
:class:`LookupIndex` precomputes what a query reads (each leaf's corner ids and positions, the frustum
rays per field of view) when a store is built or loaded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import camera
from .camera import vec3


@dataclass(frozen=True)
class LookupResult:
    """Settings chosen for one camera and budget, with their predicted error and power and flags."""

    indices: tuple[int, ...]
    packed: int
    settings: dict[str, Any]
    power_w: float
    error: float
    clamped: bool
    infeasible: bool
    corner: int = -1
    view: int = -1
    leaf: int = -1


class LookupIndex:
    """Tables derived from a store's octree for fast lookups (built once per store)."""

    def __init__(self, root_min: np.ndarray, root_size: float, lattice_depth: int, children: np.ndarray,
                 corner_coords: np.ndarray) -> None:
        key = {tuple(int(c) for c in xyz): i for i, xyz in enumerate(corner_coords)}
        side = 1 << lattice_depth
        self.lattice_depth = lattice_depth
        self.leaf_corners: dict[int, np.ndarray] = {}
        self.node_origin: dict[int, tuple[int, int, int, int]] = {}
        stack = [(0, 0, 0, 0, side)]
        while stack:
            node, x, y, z, s = stack.pop()
            self.node_origin[node] = (x, y, z, s)
            c = int(children[node])
            if c == -1:
                ids = []
                for k in range(8):
                    xyz = (x + s * (k & 1), y + s * ((k >> 1) & 1), z + s * ((k >> 2) & 1))
                    if xyz not in key:
                        raise ValueError(f"leaf {node} misses its corner at lattice {xyz}")
                    ids.append(key[xyz])
                self.leaf_corners[node] = np.asarray(ids, dtype=np.int64)
            else:
                if s < 2:
                    raise ValueError("octree deeper than the lattice")
                h = s // 2
                for k in range(8):
                    stack.append((c + k, x + h * (k & 1), y + h * ((k >> 1) & 1), z + h * ((k >> 2) & 1), h))
        self._frustum_cache: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}
        cell = root_size / side
        self._lo = tuple(float(c) for c in root_min)
        self._hi = tuple(float(c) + root_size for c in root_min)
        self._lattice_scale = side / root_size
        self._children = [int(c) for c in children]
        self.leaf_corner_pos: dict[int, list[tuple[int, tuple[float, float, float]]]] = {}
        for leaf, ids in self.leaf_corners.items():
            self.leaf_corner_pos[leaf] = [
                (int(c), tuple(float(v) for v in root_min + corner_coords[c] * cell))  # type: ignore[misc]
                for c in ids]

    def leaf_depths(self, children: np.ndarray) -> dict[int, int]:
        """Depth of every leaf (root = 0)."""
        side = 1 << self.lattice_depth
        return {n: round(math.log2(side / o[3])) for n, o in self.node_origin.items() if children[n] == -1}

    def find_leaf(self, position: Any) -> tuple[int, np.ndarray, bool]:
        """Leaf containing ``position`` (clamped into the root); returns (leaf, clamped position, clamped)."""
        p = vec3(position, "position")
        lo = self._lo
        hi = self._hi
        q = tuple(min(max(p[i], lo[i]), hi[i]) for i in range(3))
        clamped = q != p
        k_scale = self._lattice_scale
        u = [(q[i] - lo[i]) * k_scale for i in range(3)]
        node = 0
        x = y = z = 0
        s = 1 << self.lattice_depth
        children = self._children
        while children[node] != -1:
            h = s // 2
            k = int(u[0] >= x + h) | (int(u[1] >= y + h) << 1) | (int(u[2] >= z + h) << 2)
            x += h * (k & 1)
            y += h * ((k >> 1) & 1)
            z += h * ((k >> 2) & 1)
            s = h
            node = children[node] + k
        return node, np.asarray(q), clamped

    def frustum(self, vfov: float, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        key = (round(vfov, 6), round(aspect, 6))
        rays = self._frustum_cache.get(key)
        if rays is None:
            rays = camera.frustum_rays(vfov, aspect)
            if len(self._frustum_cache) > 64:
                self._frustum_cache.clear()
            self._frustum_cache[key] = rays
        return rays

    def choose_view(self, rotation: np.ndarray, vfov: float, aspect: float) -> int:
        """View-cube face that receives the largest part of the camera frustum."""
        rays, weights = self.frustum(vfov, aspect)
        return camera.frustum_face(rotation, rays, weights)

    def locate(self, position: Any, rotation: np.ndarray, vfov: float, aspect: float
               ) -> tuple[int, int, int, bool]:
        """(leaf, corner, view, clamped) a camera looks up: nearest corner of its leaf, then the face."""
        leaf, q, clamped = self.find_leaf(position)
        qx, qy, qz = float(q[0]), float(q[1]), float(q[2])
        best = math.inf
        corner = -1
        for c, (cx, cy, cz) in self.leaf_corner_pos[leaf]:
            dd = (cx - qx) ** 2 + (cy - qy) ** 2 + (cz - qz) ** 2
            if dd < best:
                best, corner = dd, c
        return leaf, corner, self.choose_view(rotation, vfov, aspect), clamped
