"""Adaptive octree over the camera path (power-budget paper, sec. 4.2, 5.2 and 5.3).

The root is the path's bounding box, padded and made cubic. Every corner carries a view cube of six
axis views; a camera sample is (corner, view), rendered with the path camera's vertical field of view
and aspect at the evaluation resolution. Each root corner view gets a Pareto frontier from NSGA-II (or
exhaustive enumeration when the space is small); every search starts from both ends of the space (the
maximum-quality setting, error 0 by definition, and the cheapest one) plus its warm start.

A node is subdivided when, for some view, two corners joined by one of its edges have frontiers that
differ by more than ``tau_e`` in error or ``tau_p`` in power (Eq. 4-7, :func:`frontier_distance`), as
long as the node is within ``max_depth`` and the camera path passes through it (plus a margin). The 19
new corners are handled in the paper's order: edge midpoints compare the edge's two corners; face
centres pair their four edge-midpoint neighbours along the two face axes; the node centre pairs its six
face-centre neighbours along the three axes. A view is optimised afresh (warm-started from the pair's
frontiers) only when a pair differs for that view; otherwise it inherits the frontier of the first
corner of the first pair. Corners shared with neighbouring nodes are created once.

``view_sampling="path"`` (the default of :class:`service.optimize.OptimizeOptions`) replaces the
paper's sampling for a known path: the corners the paper samples sit up to half a cell from the path
and their six views see what a path camera would only see from elsewhere, so their frontiers predict
the path's power and error poorly. Here the nodes holding path frames are split until their side is
at most ``path_resolution`` times the frames' median viewing distance (the distance their central ray
travels), and the runtime lookup itself (:meth:`ParetoStore.locate`) says which (corner, face) each
path frame will read. Each such sample is measured at the path camera most like the frames reading it
(their medoid by eye distance over viewing distance plus direction difference); a full search runs at
every ``path_stride``-th sample along the path and short warm-started ones in between; then every
frontier setting is also priced at ``guard_frames`` more of those frames (the ones least like the
chosen ones) and the frontier keeps each setting's worst error and power, so it bounds the frames it
serves. Faces no path frame reads inherit the frontier of the nearest sample. No frontier-difference
comparisons are made in this mode.

All searches of one stage run in lockstep, so every generation of every camera goes to the executor
as one batch. Seeds derive from the run seed and the camera, and the evaluation cache answers every
repeated render, so a rerun after an interruption replays the same decisions and resumes where it
stopped.
"""

from __future__ import annotations

import itertools
import math
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service import options
from service.evaluation import CameraSpec, Evaluator
from service.nsga import NSGA2, Archive, NSGAConfig, enumerate_space
from service.params import Indices, ParameterSpace
from service.store import (
    VIEW_FORWARD,
    VIEW_UP,
    Frontier,
    ParetoStore,
    face_of,
    quantise_directions,
    quantise_eyes,
    view_up,
)

N_VIEWS = 6
# The 12 edges of a cube as pairs of corner numbers (bit 0: +x, bit 1: +y, bit 2: +z).
CUBE_EDGES: tuple[tuple[int, int], ...] = tuple(
    (k, k | (1 << a)) for a in range(3) for k in range(8) if not k & (1 << a)
)


def aimed_directions(corner: np.ndarray, positions: np.ndarray, forwards: np.ndarray,
                     targets: np.ndarray, cell: float) -> np.ndarray:
    """Sample direction (6, 3) of each view-cube face at ``corner``, aimed like the path's cameras.

    The path frames whose forward vector falls in face k's cone (the frames a lookup would send to
    face k) vote with their *target* (the point their central ray sees), weighted by
    1 / (distance to the corner^2 + cell^2) so frames near the corner count most; face k samples the
    direction from the corner to the weighted mean target. When that direction leaves face k's
    hemisphere (the corner is on the far side of what those frames look at) the weighted mean forward
    is used instead, and a face no frame looks through keeps its axis. Unit vectors, quantised as the
    store keeps them (:func:`service.store.quantise_directions`)."""
    c = np.asarray(corner, dtype=np.float64).reshape(3)
    P = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(forwards, dtype=np.float64).reshape(-1, 3)
    T = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    if not (P.shape == F.shape == T.shape) or not (np.all(np.isfinite(P)) and np.all(np.isfinite(F))
                                                     and np.all(np.isfinite(T))):
        raise ValueError("positions, forwards and targets must be finite (N, 3) arrays of one length")
    F = F / np.maximum(np.linalg.norm(F, axis=1, keepdims=True), 1e-300)
    faces = np.asarray([face_of(f) for f in F], dtype=np.int64) if len(F) else np.zeros(0, np.int64)
    w_all = 1.0 / (((P - c) ** 2).sum(axis=1) + max(cell, 1e-9) ** 2)
    out = VIEW_FORWARD.copy()
    for k in range(6):
        sel = faces == k
        if not np.any(sel):
            continue
        w = w_all[sel] / w_all[sel].sum()
        d = (w[:, None] * T[sel]).sum(axis=0) - c
        n = float(np.linalg.norm(d))
        if n > 1e-6 and float(d @ VIEW_FORWARD[k]) / n > 0.0:
            out[k] = d / n
        else:
            m = (w[:, None] * F[sel]).sum(axis=0)
            if float(np.linalg.norm(m)) > 1e-6:
                out[k] = m / np.linalg.norm(m)
    return quantise_directions(out)


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


class Cancelled(Exception):
    """The optimisation was cancelled through ``should_cancel``."""


@dataclass
class Progress:
    """Where a run stands: views optimised of those planned so far, renders, cache hits, time."""

    views_done: int = 0
    views_planned: int = 0
    evaluations: int = 0
    cache_hits: int = 0
    elapsed_s: float = 0.0
    estimate_s: float | None = None
    phase: str = "starting"


@dataclass
class FrontierRecord:
    """A frontier as measured at one camera sample: full index vectors with error and power."""

    corner: int
    view: int
    points: list[tuple[Indices, float, float]]

    def settings(self) -> list[Indices]:
        return [x for x, _, _ in self.points]


@dataclass
class OctreeConfig:
    """Subdivision thresholds and search options of one octree build."""

    threshold_power_w: float
    threshold_error: float
    max_depth: int = 2
    min_depth: int = 0  # nodes on the path are split at least this deep, whatever their frontiers
    margin: float = 0.1  # fraction of a node's side added around it for the "path passes through" test
    pad_fraction: float = 0.1
    min_size: float = 1.0
    nsga: NSGAConfig = field(default_factory=NSGAConfig)
    exhaustive_limit: int = 512
    vfov: float = 0.6911
    width: int = 64
    height: int = 36
    # "axis": the six world axes; "aimed": see :func:`aimed_directions`; "path": see the module docstring
    view_sampling: str = "aimed"
    path_resolution: float = 0.25  # "path" sampling: leaf side <= this x the path's viewing distance there
    guard_frames: int = 2  # "path" sampling: extra path cameras of each sample its frontier is priced at
    path_stride: int = 4  # "path" sampling: a full search at every path_stride-th sample along the path
    warm_generations: int = 5  # "path" sampling: generations of the warm-started searches in between

    def __post_init__(self) -> None:
        options.check({name: getattr(self, name) for name in (
            "threshold_power_w", "threshold_error", "max_depth", "min_depth", "margin", "view_sampling",
            "path_resolution", "guard_frames")})


def frontier_distance(projected: np.ndarray, target: np.ndarray, scale: tuple[float, float]
                      ) -> tuple[float, float]:
    """Half distances d_e, d_p (Eq. 6-7): for each projected (e, p) point, the nearest point of the
    target frontier in the (e / scale_e, p / scale_p) plane; mean |e - e'| and mean |p - p'|."""
    P = np.asarray(projected, dtype=np.float64).reshape(-1, 2)
    T = np.asarray(target, dtype=np.float64).reshape(-1, 2)
    if P.shape[0] == 0 or T.shape[0] == 0:
        raise ValueError("frontiers must not be empty")
    s = np.asarray(scale, dtype=np.float64)
    d2 = (((P[:, None, :] - T[None, :, :]) / s) ** 2).sum(axis=2)
    nearest = T[np.argmin(d2, axis=1)]
    diff = np.abs(P - nearest)
    return float(diff[:, 0].mean()), float(diff[:, 1].mean())


def _camera_seed(seed: int, camera: CameraSpec) -> int:
    return (int(seed) * 1_000_003 + zlib.crc32(camera.key().encode())) % (2**63)


def densify(points: np.ndarray, step: float) -> np.ndarray:
    """Points along the polyline with gaps no longer than ``step``."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = [p[:1]]
    for a, b in itertools.pairwise(p):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
        t = (np.arange(1, n + 1) / n)[:, None]
        out.append(a + (b - a) * t)
    return np.concatenate(out)


class OctreeBuilder:
    """Builds the octree and its frontiers for one scene and path; see the module docstring."""

    def __init__(self, evaluator: Evaluator, space: ParameterSpace, path_positions: np.ndarray,
                 config: OctreeConfig, progress: Callable[[Progress], None] | None = None,
                 should_cancel: Callable[[], bool] | None = None, *,
                 path_forwards: np.ndarray | None = None, path_targets: np.ndarray | None = None,
                 path_matrices: np.ndarray | None = None, path_vfovs: np.ndarray | None = None,
                 path_aspects: np.ndarray | None = None) -> None:
        self.ev = evaluator
        self.space = space
        self.cfg = config
        self._progress_cb = progress
        self._should_cancel = should_cancel
        self.aimed = config.view_sampling == "aimed"
        self.path_mode = config.view_sampling == "path"
        if (self.aimed or self.path_mode) and (path_forwards is None or path_targets is None):
            raise ValueError(f"{config.view_sampling} view sampling needs the path's forwards and targets")
        self.path_positions = np.asarray(path_positions, dtype=np.float64).reshape(-1, 3)
        self.path_forwards = None if path_forwards is None else np.asarray(path_forwards, np.float64)
        self.path_targets = None if path_targets is None else np.asarray(path_targets, np.float64)
        n = len(self.path_positions)
        self.path_matrices = None if path_matrices is None else np.asarray(path_matrices, np.float64)
        self.path_vfovs = (np.full(n, config.vfov) if path_vfovs is None
                           else np.asarray(path_vfovs, np.float64).reshape(-1))
        self.path_aspects = (np.full(n, config.width / config.height) if path_aspects is None
                             else np.asarray(path_aspects, np.float64).reshape(-1))
        if self.path_mode and (self.path_matrices is None or self.path_matrices.shape[0] != n
                               or self.path_vfovs.shape[0] != n or self.path_aspects.shape[0] != n):
            raise ValueError("path view sampling needs one world matrix, fov and aspect per path frame")
        self.root_min, self.root_size = root_cube(path_positions, config.pad_fraction, config.min_size,
                                                  rest_on_path=self.aimed or self.path_mode)
        self.side = 1 << config.max_depth
        self.cell = self.root_size / self.side
        self.path_points = densify(path_positions, self.cell / 2)
        self.corner_index: dict[tuple[int, int, int], int] = {}
        self.corner_coords: list[tuple[int, int, int]] = []
        self.corner_views: list[list[int]] = []
        self.corner_dirs: list[np.ndarray] = []  # (6, 3) sample directions per corner
        self.frontiers: list[FrontierRecord] = []
        # nodes: (lattice origin, lattice size, depth); children[n] = first child or -1
        self.nodes: list[tuple[tuple[int, int, int], int, int]] = []
        self.children: list[int] = []
        self._dist: dict[tuple[int, int, int], tuple[float, float]] = {}
        # "path" sampling: the camera behind each optimised (corner, view)
        self.sample_cams: dict[tuple[int, int], CameraSpec] = {}
        self.sample_scale: dict[tuple[int, int], float] = {}  # median viewing distance of its frames
        self.t0 = time.perf_counter()
        self._steps_done = 0
        self._steps_planned = 0
        self.state = Progress(phase="root")

    # -- bookkeeping --------------------------------------------------------------------------------

    def _report(self, phase: str | None = None) -> None:
        if phase is not None:
            self.state.phase = phase
        s = self.state
        s.evaluations = self.ev.evaluations
        s.cache_hits = self.ev.cache_hits
        s.elapsed_s = time.perf_counter() - self.t0
        # time per search step (one generation, or one chunk of an enumeration, of one camera) so far,
        # times the steps still planned: warm-started searches are shorter than full ones
        s.estimate_s = (s.elapsed_s / self._steps_done * max(self._steps_planned - self._steps_done, 0)
                        if self._steps_done else None)
        if self._progress_cb is not None:
            self._progress_cb(Progress(**vars(s)))

    def _check_cancel(self) -> None:
        if self._should_cancel is not None and self._should_cancel():
            self._report("cancelled")
            raise Cancelled("optimisation cancelled")

    def camera(self, corner: int, view: int) -> CameraSpec:
        cam = self.sample_cams.get((corner, view))
        if cam is not None:
            return cam
        pos = self.root_min + np.asarray(self.corner_coords[corner], dtype=np.float64) * self.cell
        if not self.aimed:
            return CameraSpec(tuple(pos), tuple(VIEW_FORWARD[view]), tuple(VIEW_UP[view]), self.cfg.vfov,
                              self.cfg.width, self.cfg.height)
        f = self.corner_dirs[corner][view]
        return CameraSpec(tuple(pos), tuple(f), tuple(view_up(f)), self.cfg.vfov, self.cfg.width,
                          self.cfg.height)

    def _corner(self, xyz: tuple[int, int, int]) -> tuple[int, bool]:
        c = self.corner_index.get(xyz)
        if c is not None:
            return c, False
        c = len(self.corner_coords)
        self.corner_index[xyz] = c
        self.corner_coords.append(xyz)
        self.corner_views.append([-1] * N_VIEWS)
        if self.aimed:
            pos = self.root_min + np.asarray(xyz, dtype=np.float64) * self.cell
            assert self.path_forwards is not None and self.path_targets is not None
            self.corner_dirs.append(aimed_directions(pos, self.path_positions, self.path_forwards,
                                                     self.path_targets, self.cell))
        else:
            self.corner_dirs.append(VIEW_FORWARD.copy())
        return c, True

    def _node_box(self, node: int) -> tuple[np.ndarray, np.ndarray]:
        origin, size, _ = self.nodes[node]
        lo = self.root_min + np.asarray(origin, dtype=np.float64) * self.cell
        return lo, lo + size * self.cell

    def _on_path(self, node: int) -> bool:
        lo, hi = self._node_box(node)
        m = self.cfg.margin * (hi[0] - lo[0])
        inside = np.all((self.path_points >= lo - m) & (self.path_points <= hi + m), axis=1)
        return bool(np.any(inside))

    def _node_corners(self, node: int) -> list[int]:
        (x, y, z), s, _ = self.nodes[node]
        return [self.corner_index[(x + s * (k & 1), y + s * ((k >> 1) & 1), z + s * ((k >> 2) & 1))]
                for k in range(8)]

    # -- searches -----------------------------------------------------------------------------------

    def _search_steps(self, n_jobs: int, generations: int | None = None) -> int:
        """Steps of ``n_jobs`` searches run together: chunks of the enumeration, or NSGA-II generations."""
        if self.space.size <= self.cfg.exhaustive_limit:
            n = math.prod(self.space.free_n_values)
            return n_jobs * -(-n // max(1, 256 // max(1, n_jobs)))
        return n_jobs * (generations or self.cfg.nsga.generations)

    def _optimise(self, jobs: Sequence[tuple[int, int, list[Indices]]], phase: str,
                  generations: int | None = None, planned: bool = False) -> None:
        """Frontiers for (corner, view, warm start) jobs, all searches in lockstep (``generations``
        overrides the configured number, for short searches from a good warm start; ``planned``: their
        steps were already counted in the progress estimate)."""
        if not jobs:
            return
        steps_before = self._steps_done
        stage_steps = self._search_steps(len(jobs), generations)
        if not planned:
            self._steps_planned += stage_steps
        nv = self.space.free_n_values
        cams = [self.camera(c, v) for c, v, _ in jobs]
        archives: list[Archive]
        if self.space.size <= self.cfg.exhaustive_limit:
            xs = enumerate_space(nv)
            archives = [Archive() for _ in jobs]
            chunk = max(1, 256 // len(jobs))
            for start in range(0, len(xs), chunk):
                self._check_cancel()
                part = xs[start:start + chunk]
                reqs = [(cam, self.space.expand(x)) for cam in cams for x in part]
                res = self.ev.evaluate(reqs)
                for j in range(len(jobs)):
                    for k, x in enumerate(part):
                        ev = res[j * len(part) + k]
                        archives[j].add(x, (ev.error, ev.power_w))
                self._steps_done += len(jobs)
                self._report(phase)
        else:
            algos = []
            for (_, _, warm), cam in zip(jobs, cams, strict=True):
                cfg = NSGAConfig(self.cfg.nsga.population, generations or self.cfg.nsga.generations,
                                 self.cfg.nsga.crossover_prob, self.cfg.nsga.mutation_prob,
                                 _camera_seed(self.cfg.nsga.seed, cam))
                # both ends of the space first (max quality anchors error 0, the cheapest the low-power
                # end), then the warm start
                ends = [self.space.max_quality_indices(), self.space.min_quality_indices()]
                init = list(dict.fromkeys(self.space.restrict(w) for w in [*ends, *warm]))
                algos.append(NSGA2(nv, cfg, init[: cfg.population]))
            while True:
                self._check_cancel()
                asks = [(j, a.ask()) for j, a in enumerate(algos) if not a.done]
                asks = [(j, b) for j, b in asks if b]
                if not asks:
                    break
                reqs = [(cams[j], self.space.expand(x)) for j, b in asks for x in b]
                res = self.ev.evaluate(reqs)
                k = 0
                for j, b in asks:
                    algos[j].tell([(r.error, r.power_w) for r in res[k:k + len(b)]])
                    k += len(b)
                self._steps_done += len(asks)
                self._report(phase)
            archives = [a.archive for a in algos]
        for (c, v, _), arch in zip(jobs, archives, strict=True):
            pts = [(self.space.expand(x), e, p) for x, e, p in arch.frontier()]
            self.frontiers.append(FrontierRecord(c, v, pts))
            self.corner_views[c][v] = len(self.frontiers) - 1
            self.state.views_done += 1
        self._steps_done = max(self._steps_done, steps_before + stage_steps)  # searches that ended early
        self._report(phase)

    def _distances(self, pairs: Sequence[tuple[int, int, int]]) -> list[tuple[float, float]]:
        """D_e, D_p (Eq. 4-5) of (corner a, corner b, view) pairs, projections batched."""
        todo = [p for p in dict.fromkeys(pairs) if p not in self._dist]
        if todo:
            self._check_cancel()
            reqs = []
            for a, b, v in todo:
                fa = self.frontiers[self.corner_views[a][v]]
                fb = self.frontiers[self.corner_views[b][v]]
                reqs += [(self.camera(b, v), x) for x in fa.settings()]
                reqs += [(self.camera(a, v), x) for x in fb.settings()]
            res = self.ev.evaluate(reqs)
            k = 0
            for a, b, v in todo:
                fa = self.frontiers[self.corner_views[a][v]]
                fb = self.frontiers[self.corner_views[b][v]]
                pa = np.asarray([(r.error, r.power_w) for r in res[k:k + len(fa.points)]])
                k += len(fa.points)
                pb = np.asarray([(r.error, r.power_w) for r in res[k:k + len(fb.points)]])
                k += len(fb.points)
                ta = np.asarray([(e, p) for _, e, p in fa.points])
                tb = np.asarray([(e, p) for _, e, p in fb.points])
                allp = np.concatenate([pa, pb, ta, tb])
                scale = (max(float(np.ptp(allp[:, 0])), self.cfg.threshold_error),
                         max(float(np.ptp(allp[:, 1])), self.cfg.threshold_power_w))
                de1, dp1 = frontier_distance(pa, tb, scale)  # P_a projected to c_b against P_b
                de2, dp2 = frontier_distance(pb, ta, scale)
                self._dist[(a, b, v)] = (de1 + de2, dp1 + dp2)
            self._report()
        return [self._dist[p] for p in pairs]

    def _differs(self, d: tuple[float, float]) -> bool:
        return d[0] > self.cfg.threshold_error or d[1] > self.cfg.threshold_power_w

    # -- the build ----------------------------------------------------------------------------------

    def run(self) -> None:
        if self.path_mode:
            self._run_path()
            return
        self.nodes.append(((0, 0, 0), self.side, 0))
        self.children.append(-1)
        for k in range(8):
            self._corner((self.side * (k & 1), self.side * ((k >> 1) & 1), self.side * ((k >> 2) & 1)))
        self.state.views_planned = 8 * N_VIEWS
        self._report("root")
        self._optimise([(c, v, []) for c in range(8) for v in range(N_VIEWS)], "root")
        level = [0]
        while level:
            depth = self.nodes[level[0]][2]
            if depth >= self.cfg.max_depth:
                break
            cand = [n for n in level if self._on_path(n)]
            pairs = []
            for n in (m for m in cand if depth >= self.cfg.min_depth):
                cs = self._node_corners(n)
                pairs += [(cs[a], cs[b], v) for a, b in CUBE_EDGES for v in range(N_VIEWS)]
            self._report(f"compare depth {depth}")
            self._distances(pairs)
            split = [n for n in cand if depth < self.cfg.min_depth or any(
                self._differs(self._dist[(cs[a], cs[b], v)])
                for cs in [self._node_corners(n)] for a, b in CUBE_EDGES for v in range(N_VIEWS))]
            level = self._subdivide(split, depth + 1)
        self._report("done")

    # -- "path" sampling ------------------------------------------------------------------------------

    def _view_distances(self) -> np.ndarray:
        assert self.path_targets is not None
        d = np.linalg.norm(self.path_targets - self.path_positions, axis=1)
        return np.maximum(d, 1e-3 * self.root_size)

    def _run_path(self) -> None:
        """Split the nodes the path's frames are in until their side is at most ``path_resolution``
        times the median distance those frames look (so the lattice is fine where the camera looks at
        something near and coarse where it looks far), then optimise one sample per (corner, view) that
        some path frame looks up, at the path camera that best represents those frames."""
        self.nodes.append(((0, 0, 0), self.side, 0))
        self.children.append(-1)
        for k in range(8):
            self._corner((self.side * (k & 1), self.side * ((k >> 1) & 1), self.side * ((k >> 2) & 1)))
        dist = self._view_distances()
        level = [0]
        while level:
            depth = self.nodes[level[0]][2]
            if depth >= self.cfg.max_depth:
                break
            split = []
            for n in level:
                lo, hi = self._node_box(n)
                inside = np.all((self.path_positions >= lo) & (self.path_positions <= hi), axis=1)
                if not np.any(inside):
                    continue
                side = float(hi[0] - lo[0])
                if depth < self.cfg.min_depth or side > self.cfg.path_resolution * float(
                        np.median(dist[inside])):
                    split.append(n)
            level = self._split_plain(split, depth + 1)
        self._report("place samples")
        groups = self._group_frames()
        self.state.views_planned = len(groups)
        guards: dict[tuple[int, int], list[CameraSpec]] = {}
        order = sorted(groups, key=lambda cv: groups[cv][0])  # in path order (first frame)
        for (c, v) in order:
            frames = groups[(c, v)]
            cams = self._sample_cameras(frames, dist)
            self.sample_cams[(c, v)] = cams[0]
            self.sample_scale[(c, v)] = float(np.median(dist[frames]))
            guards[(c, v)] = cams[1:]
        # Neighbouring samples along the path see nearly the same image: a full search at every
        # ``stride``-th one, then short searches for the others, warm-started from the frontiers of
        # the full searches before and after them on the path.
        stride = max(1, self.cfg.path_stride)
        anchors = list(range(0, len(order), stride))
        if anchors and anchors[-1] != len(order) - 1 and len(order) > 1:
            anchors.append(len(order) - 1)
        warm_generations = min(self.cfg.warm_generations, self.cfg.nsga.generations)
        self._steps_planned += self._search_steps(len(order) - len(anchors), warm_generations)
        # pricing a frontier at a guard camera renders about a population's worth: one step each
        guard_steps = sum(len(g) for g in guards.values())
        self._steps_planned += guard_steps
        self._optimise([(*order[i], []) for i in anchors], "optimise path samples")
        anchor_set = set(anchors)
        jobs = []
        for i, (c, v) in enumerate(order):
            if i in anchor_set:
                continue
            before = max(a for a in anchors if a < i)
            after = min(a for a in anchors if a > i)
            fa = self.frontiers[self.corner_views[order[before][0]][order[before][1]]].settings()
            fb = self.frontiers[self.corner_views[order[after][0]][order[after][1]]].settings()
            warm = [x for pair in itertools.zip_longest(fa, fb) for x in pair if x is not None]
            jobs.append((c, v, warm))
        self._optimise(jobs, "refine path samples", generations=warm_generations, planned=True)
        self._guard(guards)
        self._steps_done += guard_steps
        self._inherit_unsampled()
        self._report("done")

    def _add_children(self, node: int, child_depth: int) -> list[int]:
        """Append ``node``'s eight children (consecutive, in the store's child order); return them."""
        (x, y, z), s, _ = self.nodes[node]
        h = s // 2
        first = len(self.nodes)
        self.children[node] = first
        for k in range(8):
            self.nodes.append(((x + h * (k & 1), y + h * ((k >> 1) & 1), z + h * ((k >> 2) & 1)), h,
                               child_depth))
            self.children.append(-1)
        return list(range(first, first + 8))

    def _split_plain(self, nodes: Sequence[int], child_depth: int) -> list[int]:
        """Split ``nodes`` and create their new corners without optimising anything."""
        children = []
        for n in nodes:
            (x, y, z), s, _ = self.nodes[n]
            h = s // 2
            children += self._add_children(n, child_depth)
            for i, j, k in itertools.product(range(3), repeat=3):
                self._corner((x + h * i, y + h * j, z + h * k))
        return children

    def _skeleton(self) -> ParetoStore:
        """The finished tree with one placeholder frontier, to ask it what a camera would look up."""
        x = self.space.max_quality_indices()
        ph = Frontier.from_points([self.space.pack(x)], [0.0], [0.0])
        return ParetoStore(
            parameters=self.space.to_stored(), root_min=self.root_min, root_size=self.root_size,
            lattice_depth=self.cfg.max_depth, children=np.asarray(self.children),
            corner_coords=np.asarray(self.corner_coords, dtype=np.int64).reshape(-1, 3),
            corner_views=np.zeros((len(self.corner_coords), N_VIEWS), dtype=np.int64), frontiers=[ph],
            vfov=self.cfg.vfov, aspect=self.cfg.width / self.cfg.height)

    def _group_frames(self) -> dict[tuple[int, int], list[int]]:
        """Path frames by the (corner, view) the runtime lookup sends them to (the store's own code)."""
        assert self.path_matrices is not None
        skel = self._skeleton()
        groups: dict[tuple[int, int], list[int]] = {}
        for i, m in enumerate(self.path_matrices):
            cv = skel.locate(self.path_positions[i], matrix=m, fov=float(self.path_vfovs[i]),
                             aspect=float(self.path_aspects[i]))
            groups.setdefault(cv, []).append(i)
        return groups

    def _sample_cameras(self, frames: Sequence[int], dist: np.ndarray) -> list[CameraSpec]:
        """The group's medoid frame (eye and view direction, distances in units of the viewing
        distance), then up to ``guard_frames`` frames farthest from the chosen ones."""
        assert self.path_forwards is not None
        idx = np.asarray(frames, dtype=np.int64)
        p = self.path_positions[idx]
        f = self.path_forwards[idx] / np.linalg.norm(self.path_forwards[idx], axis=1, keepdims=True)
        scale = float(np.median(dist[idx]))
        cost = (((p[:, None, :] - p[None, :, :]) ** 2).sum(axis=2) / scale**2
                + ((f[:, None, :] - f[None, :, :]) ** 2).sum(axis=2))
        chosen = [int(np.argmin(cost.sum(axis=1)))]
        for _ in range(self.cfg.guard_frames):
            far = cost[chosen].min(axis=0)
            k = int(np.argmax(far))
            if far[k] <= 1e-12:
                break
            chosen.append(k)
        eyes = quantise_eyes(p[chosen], self.root_min, self.root_size)
        fwd = quantise_directions(f[chosen], fine=True)
        return [CameraSpec(tuple(e), tuple(d), tuple(view_up(d)), self.cfg.vfov, self.cfg.width,
                           self.cfg.height) for e, d in zip(eyes, fwd, strict=True)]

    def _guard(self, guards: dict[tuple[int, int], list[CameraSpec]]) -> None:
        """Price every frontier setting at its sample's guard cameras too and keep, per setting, the
        worst error and power seen: the stored frontier then bounds the frames between the sample and
        its guards, not just the sample itself."""
        reqs: list[tuple[CameraSpec, Indices]] = []
        for cv, cams in guards.items():
            rec = self.frontiers[self.corner_views[cv[0]][cv[1]]]
            reqs += [(cam, x) for cam in cams for x in rec.settings()]
        if not reqs:
            return
        self._check_cancel()
        self._report("price guard frames")
        res = iter(self.ev.evaluate(reqs))
        for cv, cams in guards.items():
            rec = self.frontiers[self.corner_views[cv[0]][cv[1]]]
            e = np.asarray([pt[1] for pt in rec.points], dtype=np.float64)
            pw = np.asarray([pt[2] for pt in rec.points], dtype=np.float64)
            for _ in cams:
                r = [next(res) for _ in rec.points]
                e = np.maximum(e, [x.error for x in r])
                pw = np.maximum(pw, [x.power_w for x in r])
            # points the worst case made dominated are dropped where every record becomes a store
            # frontier (Frontier.from_points in to_store)
            rec.points = [(x, float(ei), float(pi))
                          for (x, _, _), ei, pi in zip(rec.points, e, pw, strict=True)]

    def _inherit_unsampled(self) -> None:
        """Views no path frame looks up take the frontier (and sample camera) of the sample nearest to
        them: eye distance in units of that sample's viewing distance, plus direction difference."""
        keys = list(self.sample_cams)
        eyes = np.asarray([self.sample_cams[k].eye for k in keys])
        fwd = np.asarray([self.sample_cams[k].forward for k in keys])
        scale = np.asarray([self.sample_scale[k] for k in keys])
        for c, views in enumerate(self.corner_views):
            pos = self.root_min + np.asarray(self.corner_coords[c], dtype=np.float64) * self.cell
            d_eye = ((eyes - pos) ** 2).sum(axis=1) / scale**2
            for v in range(N_VIEWS):
                if views[v] != -1:
                    continue
                k = int(np.argmin(d_eye + ((fwd - VIEW_FORWARD[v]) ** 2).sum(axis=1)))
                sc, sv = keys[k]
                views[v] = self.corner_views[sc][sv]

    def _subdivide(self, nodes: Sequence[int], child_depth: int) -> list[int]:
        """Split ``nodes``; create their new corners stage by stage; return the children."""
        stages: dict[int, list[tuple[int, list[tuple[int, int]]]]] = {1: [], 2: [], 3: []}
        children = []
        for n in nodes:
            (x, y, z), s, _ = self.nodes[n]
            h = s // 2
            children += self._add_children(n, child_depth)
            for i in range(3):
                for j in range(3):
                    for k in range(3):
                        mids = (i == 1) + (j == 1) + (k == 1)
                        if mids == 0:
                            continue
                        c, new = self._corner((x + h * i, y + h * j, z + h * k))
                        if not new:
                            continue
                        pairs = []
                        for axis, val in enumerate((i, j, k)):
                            if val != 1:
                                continue
                            lo = [x + h * i, y + h * j, z + h * k]
                            hi = list(lo)
                            lo[axis] -= h
                            hi[axis] += h
                            pairs.append((tuple(lo), tuple(hi)))
                        stages[mids].append((c, pairs))  # type: ignore[arg-type]
        for mids in (1, 2, 3):
            work = stages[mids]
            if not work:
                continue
            resolved = [(c, [(self.corner_index[a], self.corner_index[b]) for a, b in prs])
                        for c, prs in work]
            all_pairs = [(a, b, v) for _, prs in resolved for a, b in prs for v in range(N_VIEWS)]
            self._report(f"compare depth {child_depth} stage {mids}")
            self._distances(all_pairs)
            jobs = []
            for c, prs in resolved:
                for v in range(N_VIEWS):
                    diff = [(a, b) for a, b in prs if self._differs(self._dist[(a, b, v)])]
                    if diff:
                        warm: list[Indices] = []
                        for a, b in diff:
                            warm += self.frontiers[self.corner_views[a][v]].settings()
                            warm += self.frontiers[self.corner_views[b][v]].settings()
                        jobs.append((c, v, warm))
                    else:
                        self.corner_views[c][v] = self.corner_views[prs[0][0]][v]
            self.state.views_planned += len(jobs)
            self._optimise(jobs, f"optimise depth {child_depth} stage {mids}")
        return children

    # -- result -------------------------------------------------------------------------------------

    def to_store(self, *, profile: str, fps: float, aspect: float, meta: dict) -> ParetoStore:
        """The runtime store: nodes in creation order (children consecutive), shared frontiers."""
        used = sorted({f for views in self.corner_views for f in views})
        remap = {f: i for i, f in enumerate(used)}
        frontiers = []
        for f in used:
            rec = self.frontiers[f]
            frontiers.append(Frontier.from_points([self.space.pack(x) for x, _, _ in rec.points],
                                                  [min(max(e, 0.0), 1.0) for _, e, _ in rec.points],
                                                  [p for _, _, p in rec.points]))
        cams = ([self.sample_cams[(self.frontiers[f].corner, self.frontiers[f].view)] for f in used]
                if self.path_mode else [])
        return ParetoStore(
            parameters=self.space.to_stored(),
            root_min=self.root_min,
            root_size=self.root_size,
            lattice_depth=self.cfg.max_depth,
            children=np.asarray(self.children),
            corner_coords=np.asarray(self.corner_coords, dtype=np.int64).reshape(-1, 3),
            corner_views=np.asarray([[remap[f] for f in views] for views in self.corner_views]),
            frontiers=frontiers,
            vfov=self.cfg.vfov,
            aspect=aspect,
            profile=profile,
            fps=fps,
            meta=meta,
            view_dirs=np.asarray(self.corner_dirs) if self.aimed else None,
            frontier_dirs=np.asarray([c.forward for c in cams]) if cams else None,
            frontier_eyes=np.asarray([c.eye for c in cams]) if cams else None,
        )
