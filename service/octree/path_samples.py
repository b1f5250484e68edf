"""Camera samples at the path's own cameras (``view_sampling="path"``, the default).

The corners the paper samples sit up to half a cell from the path and their six views see what a path
camera would only see from elsewhere, so their frontiers predict the path's power and error poorly.
Here the nodes holding path frames are split until their side is at most ``path_resolution`` times the
frames' median viewing distance (the distance their central ray travels; ``max_depth`` caps it), and
the runtime lookup itself (:meth:`ParetoStore.locate`) says which (corner, face) each path frame will
read. Each such sample is measured at the path camera most like the frames reading it (their medoid
by eye distance over viewing distance plus direction difference); a full search runs at every
``path_stride``-th sample along the path and short warm-started ones in between (warm-started from
the neighbours' meeting tiers); then every frontier
setting is also priced at ``guard_frames`` more of those frames (the ones least like the chosen ones)
and, when there are guard frames, at the medoids of as many other passes of the path through the
sample's group (a loop's closing frames, a second walk through a room: the frames least like the chosen
ones need not fall on them; the longest passes first), then, while a frame of the group lies farther
than ``guard_radius`` from every camera chosen, at that frame too (at most ``guard_frames`` more: a fast
pan's middle frames, where interpolating between cameras misses most), and the frontier keeps each
setting's worst error, power and frame time, so it bounds the frames it serves (and each camera's own,
:class:`service.store.priced.PricedFigures`: the lookup interpolates them at a frame, and draws the
frame's tiers from the interpolated frame times). Faces
no path frame reads inherit the frontier of the nearest sample. No frontier-difference comparisons
are made in this mode.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from service.evaluation import CameraSpec
from service.params import Indices
from service.store import VIEW_FORWARD, quantise_directions, quantise_eyes, view_up
from service.store.priced import SAME_CAMERA, camera_dissimilarity

from .lattice import N_VIEWS, Lattice
from .search import Search

#: A frontier's figures at each of its pricing cameras: (cameras, the sample first; settings; error,
#: power and frame time (K, n) of each setting at each camera).
PerCamera = tuple[list[CameraSpec], list[Indices], np.ndarray, np.ndarray, np.ndarray]


class PathSampling:
    """One sample per (corner, face) the path looks up, at the path's own cameras."""

    def __init__(self, lattice: Lattice, search: Search, config: Any, path: Any) -> None:
        self.lattice, self.search, self.cfg, self.path = lattice, search, config, path
        n = len(path.positions)
        if path.forwards is None or path.targets is None:
            raise ValueError("path view sampling needs the path's forwards and targets")
        if (path.matrices is None or path.matrices.shape[0] != n or path.vfovs.shape[0] != n
                or path.aspects.shape[0] != n):
            raise ValueError("path view sampling needs one world matrix, fov and aspect per path frame")
        self.sample_cams: dict[tuple[int, int], CameraSpec] = {}  # the camera behind each sample
        self.sample_scale: dict[tuple[int, int], float] = {}  # median viewing distance of its frames
        self.guards: dict[tuple[int, int], list[CameraSpec]] = {}  # each sample's guard cameras
        self.placed = False  # every sample camera and its guards chosen (build, before the searches)
        # guards priced at the search's resolution (no display pricing): per lattice frontier id, its
        # cameras (the sample first), settings and each setting's error, power and frame time (K, n) at
        # each camera
        self.priced: dict[int, PerCamera] = {}

    def pricing_cameras(self) -> dict[int, list[CameraSpec]]:
        """Each sample's frontier with its sample camera and guard cameras."""
        return {self.lattice.corner_views[c][v]: [cam, *self.guards.get((c, v), [])]
                for (c, v), cam in self.sample_cams.items()}

    def priced_figures(self) -> dict[int, PerCamera]:
        """The guards' per-camera figures where they were priced during the build (no display pricing)."""
        return self.priced

    def pricing_scales(self) -> dict[int, float]:
        """Each sample's frontier with the median viewing distance of its frames: the distance unit of
        the camera dissimilarity its sample and guards were chosen by."""
        return {self.lattice.corner_views[c][v]: s for (c, v), s in self.sample_scale.items()}

    def pricing_plan(self) -> list[tuple[int, int]] | None:
        """Once the samples are placed (before their searches run), every sample's frontier (-1 until
        its search has run) with its camera count: the sample and its own guards."""
        if not self.placed:
            return None
        views = self.lattice.corner_views
        return [(views[c][v], 1 + len(self.guards[(c, v)])) for c, v in self.sample_cams]

    def store_cameras(self, used: list[int]) -> dict[str, Any]:
        """Every stored frontier's sample camera (format version 3)."""
        recs = [self.lattice.frontiers[f] for f in used]
        cams = [self.sample_cams[(r.corner, r.view)] for r in recs]
        if not cams:
            return {}
        return {"frontier_dirs": np.asarray([c.forward for c in cams]),
                "frontier_eyes": np.asarray([c.eye for c in cams])}

    def build(self) -> None:
        dist = self._view_distances()
        self._refine(dist)
        self.search.report("place samples")
        groups = self._group_frames()
        self.search.state.views_planned = len(groups)
        guards: dict[tuple[int, int], list[CameraSpec]] = {}
        order = sorted(groups, key=lambda cv: groups[cv][0])  # in path order (first frame)
        for (c, v) in order:
            frames = groups[(c, v)]
            cams = self._sample_cameras(frames, dist)
            self.sample_cams[(c, v)] = cams[0]
            self.sample_scale[(c, v)] = float(np.median(dist[frames]))
            guards[(c, v)] = cams[1:]
        self.guards = guards
        self.placed = True
        self._search_along(order, guards)
        if self.cfg.display is None:  # else the guards are priced at display resolution, not here
            self._guard(guards)
        if self.cfg.display is None:
            self.search.steps_done += sum(len(g) for g in guards.values())
        self._inherit_unsampled()

    def _refine(self, dist: np.ndarray) -> None:
        """Split the nodes the path's frames are in until their side is at most ``path_resolution``
        times the median distance those frames look (so the lattice is fine where the camera looks at
        something near and coarse where it looks far)."""
        lat = self.lattice
        positions = self.path.positions
        lat.add_root()
        level = [0]
        while level:
            depth = lat.depth(level[0])
            if depth >= self.cfg.max_depth:
                break
            split = []
            for n in level:
                lo, hi = lat.node_box(n)
                inside = np.all((positions >= lo) & (positions <= hi), axis=1)
                if not np.any(inside):
                    continue
                side = float(hi[0] - lo[0])
                if depth < self.cfg.min_depth or side > self.cfg.path_resolution * float(
                        np.median(dist[inside])):
                    split.append(n)
            level = lat.split(split, depth + 1)

    def _search_along(self, order: list[tuple[int, int]], guards: dict[tuple[int, int], list[CameraSpec]]
                      ) -> None:
        """Neighbouring samples along the path see nearly the same image: a full search at every
        ``stride``-th one, then short searches for the others, warm-started from the frontiers of the
        full searches before and after them on the path."""
        lat, search = self.lattice, self.search
        stride = max(1, self.cfg.path_stride)
        anchors = list(range(0, len(order), stride))
        if anchors and anchors[-1] != len(order) - 1 and len(order) > 1:
            anchors.append(len(order) - 1)
        warm_generations = min(self.cfg.warm_generations, self.cfg.nsga.generations)
        search.steps_planned += search.steps(len(order) - len(anchors), warm_generations)
        # pricing a frontier at a guard camera renders about a population's worth: one step each
        if self.cfg.display is None:
            search.steps_planned += sum(len(g) for g in guards.values())
        self._optimise([(*order[i], []) for i in anchors], "optimise path samples")
        anchor_set = set(anchors)
        jobs = []
        for i, (c, v) in enumerate(order):
            if i in anchor_set:
                continue
            before = max(a for a in anchors if a < i)
            after = min(a for a in anchors if a > i)
            fa = [pt[0] for pt in search.meeting_tier(lat.frontier(*order[before]).points)]
            fb = [pt[0] for pt in search.meeting_tier(lat.frontier(*order[after]).points)]
            warm = [x for pair in itertools.zip_longest(fa, fb) for x in pair if x is not None]
            jobs.append((c, v, warm))
        self._optimise(jobs, "refine path samples", generations=warm_generations, planned=True)

    def _optimise(self, jobs: Sequence[tuple[int, int, list[Indices]]], phase: str,
                  generations: int | None = None, planned: bool = False) -> None:
        found = self.search.run([self.sample_cams[(c, v)] for c, v, _ in jobs], [w for _, _, w in jobs],
                                phase, generations, planned)
        for (c, v, _), got in zip(jobs, found, strict=True):
            self.lattice.set_frontier(c, v, got.points, got.kept_up, got.near)

    def _view_distances(self) -> np.ndarray:
        d = np.linalg.norm(self.path.targets - self.path.positions, axis=1)
        return np.maximum(d, 1e-3 * self.lattice.root_size)

    def _group_frames(self) -> dict[tuple[int, int], list[int]]:
        """Path frames by the (corner, view) the runtime lookup sends them to (the store's own code)."""
        skel = self.lattice.skeleton(self.search.space, vfov=self.cfg.vfov,
                                     aspect=self.cfg.width / self.cfg.height)
        groups: dict[tuple[int, int], list[int]] = {}
        for i, m in enumerate(self.path.matrices):
            cv = skel.locate(self.path.positions[i], matrix=m, fov=float(self.path.vfovs[i]),
                             aspect=float(self.path.aspects[i]))
            groups.setdefault(cv, []).append(i)
        return groups

    def _sample_cameras(self, frames: Sequence[int], dist: np.ndarray) -> list[CameraSpec]:
        """The group's medoid frame (eye and view direction, distances in units of the viewing
        distance); with guard frames, the medoids of up to ``guard_frames`` other passes of the path
        through the group (:func:`_pass_medoids`), then up to ``guard_frames`` frames farthest from the
        chosen ones, then up to ``guard_frames`` more while the farthest lies beyond ``guard_radius``.

        The radius is for a group whose frames the others leave far from every camera: on the hall
        (640x360) frames 1404-1407 turn 20 degrees a frame, and frame 1406, 0.12 from its frontier's
        three cameras, measured 0.064 for a predicted 0.029, a quarter of the power-budget mode's mean
        error prediction over 45 frames (bench/RESULTS.md)."""
        idx = np.asarray(frames, dtype=np.int64)
        p = self.path.positions[idx]
        f = self.path.forwards[idx] / np.linalg.norm(self.path.forwards[idx], axis=1, keepdims=True)
        scale = float(np.median(dist[idx]))
        cost = camera_dissimilarity(p[:, None, :], f[:, None, :], p[None, :, :], f[None, :, :], scale)
        chosen = [_medoid(cost, np.arange(idx.size))]
        if self.cfg.guard_frames > 0:
            chosen += _pass_medoids(idx, cost, chosen[0], self.cfg.guard_frames)
        chosen += _farthest(cost, chosen, self.cfg.guard_frames, SAME_CAMERA)
        if self.cfg.guard_radius > 0:  # (at most guard_frames more: none without guard frames)
            chosen += _farthest(cost, chosen, self.cfg.guard_frames, self.cfg.guard_radius)
        eyes = quantise_eyes(p[chosen], self.lattice.root_min, self.lattice.root_size)
        fwd = quantise_directions(f[chosen], fine=True)
        return [CameraSpec(tuple(e), tuple(d), tuple(view_up(d)), self.cfg.vfov, self.cfg.width,
                           self.cfg.height) for e, d in zip(eyes, fwd, strict=True)]

    def _guard(self, guards: dict[tuple[int, int], list[CameraSpec]]) -> None:
        """Price every frontier setting at its sample's guard cameras too and keep, per setting, the
        worst error, power and frame time seen: the stored frontier then bounds the frames between the
        sample and its guards, not just the sample itself."""
        reqs: list[tuple[CameraSpec, Indices]] = []
        for cv, cams in guards.items():
            rec = self.lattice.frontier(*cv)
            reqs += [(cam, x) for cam in cams for x in rec.settings()]
        if not reqs:
            return
        self.search.check_cancel()
        self.search.report("price guard frames")
        res = iter(self.search.evaluate(reqs))
        for cv, cams in guards.items():
            rec = self.lattice.frontier(*cv)
            rows = [[(pt[1], pt[2], pt[3]) for pt in rec.points]]  # the sample's own figures first
            for _ in cams:
                rows.append([(x.error, x.power_w, x.frame_time_s) for x in (next(res) for _ in rec.points)])
            err, pw, ft = (np.asarray([[f[i] for f in row] for row in rows], dtype=np.float64)
                           .reshape(len(rows), len(rec.points)) for i in range(3))
            xs = [pt[0] for pt in rec.points]
            # points the worst case made dominated within their tier (a point may also change tier: too
            # slow for the frame rate now) are dropped where every record becomes a store frontier
            # (Frontier.from_points in to_store)
            worst = zip(xs, err.max(axis=0), pw.max(axis=0), ft.max(axis=0), strict=True)
            rec.points = [(x, float(ei), float(pi), float(ti)) for x, ei, pi, ti in worst]
            if cams:  # and each camera's own figures, to predict a frame between them
                self.priced[self.lattice.corner_views[cv[0]][cv[1]]] = ([self.sample_cams[cv], *cams], xs,
                                                                        err, pw, ft)

    def _inherit_unsampled(self) -> None:
        """Views no path frame looks up take the frontier (and sample camera) of the sample nearest to
        them: eye distance in units of that sample's viewing distance, plus direction difference."""
        keys = list(self.sample_cams)
        eyes = np.asarray([self.sample_cams[k].eye for k in keys])
        fwd = np.asarray([self.sample_cams[k].forward for k in keys])
        scale = np.asarray([self.sample_scale[k] for k in keys])
        for c, views in enumerate(self.lattice.corner_views):
            pos = self.lattice.position(c)
            d_eye = ((eyes - pos) ** 2).sum(axis=1) / scale**2
            for v in range(N_VIEWS):
                if views[v] != -1:
                    continue
                k = int(np.argmin(d_eye + ((fwd - VIEW_FORWARD[v]) ** 2).sum(axis=1)))
                sc, sv = keys[k]
                views[v] = self.lattice.corner_views[sc][sv]


def _pass_medoids(frames: np.ndarray, cost: np.ndarray, sample: int, most: int) -> list[int]:
    """The medoids of up to ``most`` passes of the path through a group (runs of consecutive path frames)
    other than the sample's own, the longest passes first, as positions in ``frames``.

    A path that comes back to a lookup cell later (a loop's closing frames, a second walk through a
    room) reads the same frontier from another place or pitch, and the dissimilarity's farthest frames
    need not fall on that pass: on the hall a frame 0.65 m to the side and 0.048 from the sample by that
    measure read a frontier priced only on the other pass and measured twice its worst camera's error
    (bench/RESULTS.md). A pass coinciding with a camera already chosen adds none; ``most`` bounds the
    cost where a camera wavers across a cell's border (each crossing a pass)."""
    runs = np.split(np.arange(frames.size), np.flatnonzero(np.diff(frames) > 1) + 1)
    others = sorted((run for run in runs if sample not in run), key=len, reverse=True)  # stable: path order
    chosen = [sample]
    for run in others:
        if len(chosen) > most:
            break
        m = _medoid(cost, run)
        if cost[chosen, m].min() > SAME_CAMERA:
            chosen.append(m)
    return chosen[1:]


def _farthest(cost: np.ndarray, chosen: list[int], most: int, beyond: float) -> list[int]:
    """Up to ``most`` more positions in ``cost``, each the one least like those chosen so far, while it
    is more than ``beyond`` from all of them (the farthest-point rule: with ``beyond`` at
    :data:`SAME_CAMERA`, the guard frames; with the guard radius, the frames that still lie outside it)."""
    added: list[int] = []
    for _ in range(most):
        far = cost[chosen + added].min(axis=0)
        k = int(np.argmax(far))
        if far[k] <= beyond:
            break
        added.append(k)
    return added


def _medoid(cost: np.ndarray, members: np.ndarray) -> int:
    """The member least unlike the others (least summed ``cost``), as a position in ``cost``."""
    return int(members[np.argmin(cost[np.ix_(members, members)].sum(axis=1))])
