"""The paper's camera samples (power-budget paper, sec. 4.2, 5.2 and 5.3): a view cube of six views at
every corner, the octree split where neighbouring corners' frontiers differ.

Every root corner view gets a frontier. A node is subdivided when, for some view, two corners joined
by one of its edges have frontiers that differ by more than ``tau_e`` in error or ``tau_p`` in power
(Eq. 4-7, :func:`frontier_distance`), as long as the node is within ``max_depth`` (here the split
depth) and the camera path passes through it (plus a margin). The 19 new corners are handled in the
paper's order: edge midpoints compare the edge's two corners; face centres pair their four
edge-midpoint neighbours along the two face axes; the node centre pairs its six face-centre neighbours
along the three axes. A view is optimised afresh (warm-started from the pair's frontiers) only when a
pair differs for that view; otherwise it inherits the frontier of the first corner of the first pair.
Comparisons and warm starts read each frontier's meeting tier (:meth:`.search.Search.meeting_tier`):
the slow tier a frontier keeps for budget-first lookups does not steer the refinement.

``"axis"`` renders view k along world axis k; ``"aimed"`` renders it along the direction from the
corner to what the path frames looking through face k see (:func:`aimed_directions`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from service.evaluation import CameraSpec
from service.params import Indices
from service.store import VIEW_FORWARD, VIEW_UP, face_of, quantise_directions, view_up

from .lattice import CUBE_EDGES, N_VIEWS, Lattice, densify
from .search import Search


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


class ViewCubeSampling:
    """Six views per corner, frontier-difference refinement (``view_sampling`` "axis" or "aimed")."""

    def __init__(self, lattice: Lattice, search: Search, config: Any, path: Any) -> None:
        self.lattice, self.search, self.cfg, self.path = lattice, search, config, path
        self.aimed = config.view_sampling == "aimed"
        if self.aimed and (path.forwards is None or path.targets is None):
            raise ValueError("aimed view sampling needs the path's forwards and targets")
        self.path_points = densify(path.positions, lattice.cell / 2)
        self._dirs: dict[int, np.ndarray] = {}  # aimed: (6, 3) sample directions per corner
        self._dist: dict[tuple[int, int, int], tuple[float, float]] = {}

    def corner_dirs(self, corner: int) -> np.ndarray:
        """Sample direction (6, 3) of each view of a corner."""
        if not self.aimed:
            return VIEW_FORWARD.copy()
        d = self._dirs.get(corner)
        if d is None:
            p = self.path
            d = self._dirs[corner] = aimed_directions(self.lattice.position(corner), p.positions, p.forwards,
                                                      p.targets, self.lattice.cell)
        return d

    def camera(self, corner: int, view: int) -> CameraSpec:
        pos = self.lattice.position(corner)
        cfg = self.cfg
        if not self.aimed:
            return CameraSpec(tuple(pos), tuple(VIEW_FORWARD[view]), tuple(VIEW_UP[view]), cfg.vfov,
                              cfg.width, cfg.height)
        f = self.corner_dirs(corner)[view]
        return CameraSpec(tuple(pos), tuple(f), tuple(view_up(f)), cfg.vfov, cfg.width, cfg.height)

    def store_cameras(self, used: list[int]) -> dict[str, Any]:
        """Aimed stores keep every corner's six sample directions (format version 2)."""
        if not self.aimed:
            return {}
        corners = range(len(self.lattice.corner_coords))
        return {"view_dirs": np.asarray([self.corner_dirs(c) for c in corners])}

    def pricing_cameras(self) -> dict[int, list[CameraSpec]]:
        """Each measured frontier with the corner view camera it was measured at."""
        return {fid: [self.camera(rec.corner, rec.view)] for fid, rec in enumerate(self.lattice.frontiers)}

    def priced_figures(self) -> dict[int, Any]:
        """None: every frontier is priced at its one corner view camera."""
        return {}

    def pricing_scales(self) -> dict[int, float]:
        """None: every frontier is priced at its one corner view camera."""
        return {}

    def pricing_plan(self) -> None:
        """Not known before the search ends: the refinement decides which views are measured."""
        return None

    def _optimise(self, jobs: Sequence[tuple[int, int, list[Indices]]], phase: str) -> None:
        found = self.search.run([self.camera(c, v) for c, v, _ in jobs], [w for _, _, w in jobs], phase)
        for (c, v, _), got in zip(jobs, found, strict=True):
            self.lattice.set_frontier(c, v, got.points, got.kept_up, got.near)

    def _on_path(self, node: int) -> bool:
        lo, hi = self.lattice.node_box(node)
        m = self.cfg.margin * (hi[0] - lo[0])
        inside = np.all((self.path_points >= lo - m) & (self.path_points <= hi + m), axis=1)
        return bool(np.any(inside))

    def build(self) -> None:
        lat, search = self.lattice, self.search
        lat.add_root()
        search.state.views_planned = 8 * N_VIEWS
        search.report("root")
        self._optimise([(c, v, []) for c in range(8) for v in range(N_VIEWS)], "root")
        level = [0]
        while level:
            depth = lat.depth(level[0])
            if depth >= self.cfg.max_depth:
                break
            cand = [n for n in level if self._on_path(n)]
            pairs = []
            for n in (m for m in cand if depth >= self.cfg.min_depth):
                cs = lat.node_corners(n)
                pairs += [(cs[a], cs[b], v) for a, b in CUBE_EDGES for v in range(N_VIEWS)]
            search.report(f"compare depth {depth}")
            self._distances(pairs)
            split = [n for n in cand if depth < self.cfg.min_depth or any(
                self._differs(self._dist[(cs[a], cs[b], v)])
                for cs in [lat.node_corners(n)] for a, b in CUBE_EDGES for v in range(N_VIEWS))]
            level = self._subdivide(split, depth + 1)

    def _distances(self, pairs: Sequence[tuple[int, int, int]]) -> list[tuple[float, float]]:
        """D_e, D_p (Eq. 4-5) of (corner a, corner b, view) pairs, projections batched."""
        todo = [p for p in dict.fromkeys(pairs) if p not in self._dist]
        if todo:
            self.search.check_cancel()
            reqs = []
            for a, b, v in todo:
                fa, fb = self._compared(a, v), self._compared(b, v)
                reqs += [(self.camera(b, v), pt[0]) for pt in fa]
                reqs += [(self.camera(a, v), pt[0]) for pt in fb]
            res = self.search.evaluate(reqs)
            k = 0
            for a, b, v in todo:
                fa, fb = self._compared(a, v), self._compared(b, v)
                pa = np.asarray([(r.error, r.power_w) for r in res[k:k + len(fa)]])
                k += len(fa)
                pb = np.asarray([(r.error, r.power_w) for r in res[k:k + len(fb)]])
                k += len(fb)
                ta = np.asarray([(pt[1], pt[2]) for pt in fa])
                tb = np.asarray([(pt[1], pt[2]) for pt in fb])
                allp = np.concatenate([pa, pb, ta, tb])
                scale = (max(float(np.ptp(allp[:, 0])), self.cfg.threshold_error),
                         max(float(np.ptp(allp[:, 1])), self.cfg.threshold_power_w))
                de1, dp1 = frontier_distance(pa, tb, scale)  # P_a projected to c_b against P_b
                de2, dp2 = frontier_distance(pb, ta, scale)
                self._dist[(a, b, v)] = (de1 + de2, dp1 + dp2)
            self.search.report()
        return [self._dist[p] for p in pairs]

    def _compared(self, corner: int, view: int) -> list[tuple[Indices, float, float, float]]:
        """The points of a (corner, view) frontier that comparisons and warm starts read: its meeting
        tier (:meth:`Search.meeting_tier`)."""
        return self.search.meeting_tier(self.lattice.frontier(corner, view).points)

    def _differs(self, d: tuple[float, float]) -> bool:
        return d[0] > self.cfg.threshold_error or d[1] > self.cfg.threshold_power_w

    def _subdivide(self, nodes: Sequence[int], child_depth: int) -> list[int]:
        """Split ``nodes``; create their new corners stage by stage; return the children."""
        stages: dict[int, list[tuple[int, list[tuple[int, int]]]]] = {1: [], 2: [], 3: []}
        children = []
        for n in nodes:
            (x, y, z), s, _ = self.lattice.nodes[n]
            h = s // 2
            children += self.lattice.add_children(n, child_depth)
            for i in range(3):
                for j in range(3):
                    for k in range(3):
                        mids = (i == 1) + (j == 1) + (k == 1)
                        if mids == 0:
                            continue
                        c, new = self.lattice.corner((x + h * i, y + h * j, z + h * k))
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
            resolved = [(c, [(self.lattice.corner_index[a], self.lattice.corner_index[b]) for a, b in prs])
                        for c, prs in work]
            all_pairs = [(a, b, v) for _, prs in resolved for a, b in prs for v in range(N_VIEWS)]
            self.search.report(f"compare depth {child_depth} stage {mids}")
            self._distances(all_pairs)
            jobs = []
            for c, prs in resolved:
                for v in range(N_VIEWS):
                    diff = [(a, b) for a, b in prs if self._differs(self._dist[(a, b, v)])]
                    if diff:
                        warm: list[Indices] = []
                        for a, b in diff:
                            warm += [pt[0] for pt in self._compared(a, v)]
                            warm += [pt[0] for pt in self._compared(b, v)]
                        jobs.append((c, v, warm))
                    else:
                        self.lattice.corner_views[c][v] = self.lattice.corner_views[prs[0][0]][v]
            self.search.state.views_planned += len(jobs)
            self._optimise(jobs, f"optimise depth {child_depth} stage {mids}")
        return children

