"""The octree's lattice: the root cube around the path, nodes split into eight consecutive children,
corners shared between neighbouring nodes on an integer lattice of ``2**max_depth`` cells per side,
and the frontier measured or inherited at each (corner, view)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service.params import Indices, ParameterSpace
from service.store import Frontier, ParetoStore
from service.store.format import box_corners, split_points

N_VIEWS = 6
# The 12 edges of a cube as pairs of corner numbers (bit 0: +x, bit 1: +y, bit 2: +z).
CUBE_EDGES: tuple[tuple[int, int], ...] = tuple(
    (k, k | (1 << a)) for a in range(3) for k in range(8) if not k & (1 << a)
)


def root_cube(positions: Any, pad_fraction: float = 0.1, min_size: float = 1.0, *,
              rest_on_path: bool = False) -> tuple[np.ndarray, float]:
    """Cubic root box around camera positions: the bounding box, padded by ``pad_fraction`` of its
    largest side on every side, made cubic about its centre; at least ``min_size`` wide so that
    degenerate paths (one point, a line, a plane) still get a proper cube. Returns (min corner, side).

    ``rest_on_path`` lifts the cube so its bottom lies below the path's lowest point by
    ``pad_fraction`` of the path's *vertical* extent instead of centring it vertically: for a flat
    path (a walk or an orbit above a floor) the lower corners then stay near camera height rather
    than far below the ground."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if p.shape[0] == 0 or not np.all(np.isfinite(p)):
        raise ValueError("need at least one finite position")
    if not (pad_fraction >= 0 and min_size > 0):
        raise ValueError("pad_fraction must be >= 0 and min_size > 0")
    lo, hi = p.min(axis=0), p.max(axis=0)
    extent = float((hi - lo).max())
    size = max(extent * (1.0 + 2.0 * pad_fraction), float(min_size))
    centre = (lo + hi) / 2
    root_min = centre - size / 2
    if rest_on_path:
        root_min[2] = max(root_min[2], lo[2] - pad_fraction * float(hi[2] - lo[2]))
    return root_min, size


def densify(points: np.ndarray, step: float) -> np.ndarray:
    """Points along the polyline with gaps no longer than ``step``."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = [p[:1]]
    for a, b in itertools.pairwise(p):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
        t = (np.arange(1, n + 1) / n)[:, None]
        out.append(a + (b - a) * t)
    return np.concatenate(out)


@dataclass
class FrontierRecord:
    """A frontier as measured at one camera sample: full index vectors with error, power and frame time;
    ``kept_up``: the search's probes that kept up with the frame rate there, left out of ``points``
    (:class:`.search.Found`), and ``near``: its slow settings near the deadline, which only the display
    pricing reads."""

    corner: int
    view: int
    points: list[tuple[Indices, float, float, float]]
    kept_up: list[tuple[Indices, float, float, float]] = field(default_factory=list)
    near: list[tuple[Indices, float, float, float]] = field(default_factory=list)

    def settings(self) -> list[Indices]:
        return [pt[0] for pt in self.points]


class Lattice:
    """Nodes, corners and the frontier of every (corner, view), in creation order (which the store
    keeps: children consecutive, corners in the order they were first needed)."""

    def __init__(self, root_min: np.ndarray, root_size: float, max_depth: int) -> None:
        self.root_min, self.root_size, self.max_depth = root_min, root_size, max_depth
        self.side = 1 << max_depth
        self.cell = self.root_size / self.side
        self.corner_index: dict[tuple[int, int, int], int] = {}
        self.corner_coords: list[tuple[int, int, int]] = []
        self.corner_views: list[list[int]] = []  # frontier id per view; -1 until measured or inherited
        self.frontiers: list[FrontierRecord] = []
        # nodes: (lattice origin, lattice size, depth); children[n] = first child or -1
        self.nodes: list[tuple[tuple[int, int, int], int, int]] = []
        self.children: list[int] = []

    def add_root(self) -> None:
        """The root node and its eight corners."""
        self.nodes.append(((0, 0, 0), self.side, 0))
        self.children.append(-1)
        for xyz in box_corners((0, 0, 0), self.side):
            self.corner(xyz)

    def corner(self, xyz: tuple[int, int, int]) -> tuple[int, bool]:
        """The corner at lattice point ``xyz`` (created if new): (id, created)."""
        c = self.corner_index.get(xyz)
        if c is not None:
            return c, False
        c = len(self.corner_coords)
        self.corner_index[xyz] = c
        self.corner_coords.append(xyz)
        self.corner_views.append([-1] * N_VIEWS)
        return c, True

    def position(self, corner_or_xyz: int | tuple[int, int, int]) -> np.ndarray:
        """World position of a corner (by id) or of a lattice point."""
        xyz = self.corner_coords[corner_or_xyz] if isinstance(corner_or_xyz, int) else corner_or_xyz
        return self.root_min + np.asarray(xyz, dtype=np.float64) * self.cell

    def node_box(self, node: int) -> tuple[np.ndarray, np.ndarray]:
        origin, size, _ = self.nodes[node]
        lo = self.root_min + np.asarray(origin, dtype=np.float64) * self.cell
        return lo, lo + size * self.cell

    def node_corners(self, node: int) -> list[int]:
        origin, s, _ = self.nodes[node]
        return [self.corner_index[xyz] for xyz in box_corners(origin, s)]

    def depth(self, node: int) -> int:
        return self.nodes[node][2]

    def add_children(self, node: int, child_depth: int) -> list[int]:
        """Append ``node``'s eight children (consecutive, in the store's child order); return them."""
        origin, s, _ = self.nodes[node]
        first = len(self.nodes)
        self.children[node] = first
        for child in box_corners(origin, s // 2):
            self.nodes.append((child, s // 2, child_depth))
            self.children.append(-1)
        return list(range(first, first + 8))

    def split(self, nodes: Sequence[int], child_depth: int) -> list[int]:
        """Split ``nodes`` and create their new corners (nothing measured); return the children."""
        children = []
        for n in nodes:
            origin, s, _ = self.nodes[n]
            children += self.add_children(n, child_depth)
            for xyz in split_points(origin, s):
                self.corner(xyz)
        return children

    def set_frontier(self, corner: int, view: int, points: list[tuple[Indices, float, float, float]],
                     kept_up: Sequence[tuple[Indices, float, float, float]] = (),
                     near: Sequence[tuple[Indices, float, float, float]] = ()) -> None:
        """Record a frontier measured for (corner, view), with the search's probes that kept up there and
        its slow settings near the deadline."""
        self.frontiers.append(FrontierRecord(corner, view, points, list(kept_up), list(near)))
        self.corner_views[corner][view] = len(self.frontiers) - 1

    def frontier(self, corner: int, view: int) -> FrontierRecord:
        return self.frontiers[self.corner_views[corner][view]]

    def store(self, space: ParameterSpace, *, vfov: float, aspect: float, profile: str = "mobile",
              fps: float = 30.0, meta: dict | None = None,
              cameras: Any = None, priced: Any = None) -> ParetoStore:
        """The runtime store: nodes in creation order, the frontiers in use (shared where inherited),
        the sample cameras ``cameras(used frontier ids)`` gives (store fields by name) and the per-camera
        figures ``priced(frontier id, store frontier)`` gives (``PricedFigures`` or None), if any."""
        used = sorted({f for views in self.corner_views for f in views})
        remap = {f: i for i, f in enumerate(used)}
        frontiers = []
        for f in used:
            rec = self.frontiers[f]
            frontiers.append(Frontier.from_points([space.pack(pt[0]) for pt in rec.points],
                                                  [min(max(pt[1], 0.0), 1.0) for pt in rec.points],
                                                  [pt[2] for pt in rec.points], [pt[3] for pt in rec.points],
                                                  fps=fps))
        return ParetoStore(
            parameters=space.to_stored(), root_min=self.root_min, root_size=self.root_size,
            lattice_depth=self.max_depth, children=np.asarray(self.children),
            corner_coords=np.asarray(self.corner_coords, dtype=np.int64).reshape(-1, 3),
            corner_views=np.asarray([[remap[f] for f in views] for views in self.corner_views]),
            frontiers=frontiers, vfov=vfov, aspect=aspect, profile=profile, fps=fps, meta=meta or {},
            **(cameras(used) if cameras is not None else {}),
            priced=None if priced is None else [priced(f, fr) for f, fr in zip(used, frontiers, strict=True)])

    def skeleton(self, space: ParameterSpace, *, vfov: float, aspect: float) -> ParetoStore:
        """The tree so far with one placeholder frontier, to ask it what a camera would look up."""
        x = space.max_quality_indices()
        ph = Frontier.from_points([space.pack(x)], [0.0], [0.0])
        return ParetoStore(
            parameters=space.to_stored(), root_min=self.root_min, root_size=self.root_size,
            lattice_depth=self.max_depth, children=np.asarray(self.children),
            corner_coords=np.asarray(self.corner_coords, dtype=np.int64).reshape(-1, 3),
            corner_views=np.zeros((len(self.corner_coords), N_VIEWS), dtype=np.int64), frontiers=[ph],
            vfov=vfov, aspect=aspect)
