"""The runtime lookup: a camera pose and a budget -> the settings a store holds for it.

The work per query: the camera's rotation (plain floats, :func:`service.store.camera.rotation_floats`),
a descent of a few octree levels to the leaf holding the camera, the nearest of the leaf's eight
corners, the view-cube face that receives most of the camera's frustum
(:func:`service.store.camera.frustum_face`: one matrix product over 64 rays) and a binary search on
that (corner, face)'s frontier. :class:`LookupIndex` precomputes what a query reads: each leaf's corner
ids and positions, the frustum rays per field of view, each frontier as plain lists and each packed
setting's values, so a query makes one numpy call (the face) and no other allocation of note.

The frame-rate target is the store's ``fps`` (what its power was priced for) unless a query asks for
another rate: then each point's power is repriced for that rate (:func:`.frame_rate.power_at_rate`, from
the store's static power) and the frontier's tiers drawn again at that rate (a slow point of the store
may meet a lower rate). Where a frontier knows its frame times, it has a meeting tier and a slow tier
(:mod:`.frontier`), and the query's priority (:data:`service.options.QUERY_PRIORITY`) says how they are
searched.

Which points are in which tier: the stored frame time of a path-sampled frontier's point is the worst
over the cameras the frontier was priced at, so by it a point that keeps up at the sample camera and
misses the rate at one far guard is slow for every frame the frontier serves. Where the store keeps
each point's frame time at each pricing camera (:class:`.priced.PricedFigures`), the tiers are the
*frame's*: each point's frame time is predicted at the query's camera by the same Shepard weights as
its error and power (:meth:`.priced.PricedFigures.frame_time`), the points predicted to meet the target
are the frame's meeting tier and the rest its slow tier, both drawn by the one two-tier rule
(:func:`.frontier.frontier_tiers`) over the stored points' stored, worst error and power (the budgets
are checked against those, as before). The result's ``frame_time_s``, ``fps`` and ``meets_fps`` are
then the frame's prediction, and ``LookupResult.meeting`` names the frame's tiers (bit ``j``: stored
point ``j`` predicted to meet), so :meth:`LookupIndex.budget_points` lists that frame's tier whatever
was looked up since. The per-query work is small: a point whose cameras all keep up (or all miss)
needs no interpolation, the few others one sum each, and a frame whose prediction agrees with the
stored frame times searches the store's own tiers (other frames' tiers are drawn once per frontier,
rate and mask, and kept: :class:`_FrameTiers`). Without per-camera frame times (stores made before, or
frontiers priced at one camera) the tiers are the stored frame times', exactly as before. The rules
below hold for either:

- ``"frame_rate"`` (the default): the budget search runs over the meeting tier (all points when none
  meets the target), so a setting that misses the target is never picked while one meets it;
- ``"budget"``: the same search first; only when no meeting point keeps the budget, the slow tier's
  points that keep it are searched the same way (least power under an error budget, least error under a
  power budget; ``meets_fps`` False). Only when no point of either tier keeps the budget is the result
  infeasible, with the same fallback as under ``"frame_rate"``.

The result says whether the chosen setting meets the target and the frame rate it reaches. A store
keeps, per view, the points of its two tiers at its own ``fps`` by the stored (worst) frame times:
another rate, and the frame's own tiers, choose among those (at a higher rate, a setting the store
dropped because it missed its own rate and was less accurate than a real-time one is not there to be
found; nor is a point the stored slow tier dropped as dominated although it keeps up near its sample
camera).

:meth:`LookupIndex.budget_points` lists the points of the tier a result came from that keep its budget:
the settings the temporal filter (:mod:`.temporal`) may show while it moves to the target.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from . import camera
from .frame_rate import frame_rate_reached, meets_frame_rate, power_at_rate
from .frontier import Frontier, frontier_tiers
from .packing import StoredParameter, settings_of, unpack_indices

if TYPE_CHECKING:
    from .priced import PricedFigures


def lowered_budget(budget: float, error_margin: float = 0.0, power_margin: float = 0.0) -> float:
    """The budget a lookup searches: an error budget less its margin (absolute, 1 - SSIM), a power budget
    less its margin's share of it (a lookup passes the margin of its budget's kind only)."""
    return (budget - error_margin) * (1.0 - power_margin)


@dataclass(frozen=True)
class LookupResult:
    """Settings chosen for one camera and budget, with their predicted error, power (at the frame rate
    they reach), frame time and flags. ``infeasible``: no setting keeps the budget (the nearest one is
    chosen). ``meets_fps``: the setting keeps up with the frame-rate target ``fps_target``; False when no
    setting of the frontier does or, under the ``"budget"`` ``priority``, when only settings that miss
    it keep the budget (under ``"frame_rate"`` a missing one is never picked otherwise); None when the
    store does not know frame times (format before 4), as are ``frame_time_s`` and ``fps`` (the frame
    rate reached). An error budget is searched less the query's ``error_margin``, a power budget less its
    ``power_margin`` share (``searched_budget``: ``infeasible`` then says no setting lies under that).
    Where the store keeps per-camera frame times, these three are the prediction for this camera, and
    ``meeting`` names this frame's tiers (bit ``j``:
    the stored frontier's point ``j`` is predicted to meet ``fps_target`` here; -1: the tiers of the
    stored frame times). ``frontier``,
    ``rank`` (the point's place in the tier it came from), ``budget_mode``, ``budget``, ``priority`` and
    ``meeting`` say where it came from (:meth:`LookupIndex.budget_points`).

    ``error`` and ``power_w`` are the frontier's stored figures, the worst over the cameras it was
    priced at: what the budget was checked against. ``expected_error`` and ``expected_power_w`` are the
    prediction for this camera (:mod:`.priced`: the pricing cameras' figures interpolated at it with
    ``weights``, one per pricing camera); the stored figures where the store keeps no per-camera
    figures (``weights`` empty)."""

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
    frame_time_s: float | None = None
    fps: float | None = None
    meets_fps: bool | None = None
    fps_target: float | None = None
    frontier: int = -1
    rank: int = -1
    budget_mode: str = ""
    budget: float = math.nan
    priority: str = "frame_rate"  # the query's (service.options.QUERY_PRIORITY)
    expected_error: float = math.nan
    expected_power_w: float = math.nan
    weights: tuple[float, ...] = ()
    meeting: int = -1
    error_margin: float = 0.0  # the query's (service.options.QUERY_ERROR_MARGIN); error budgets only
    power_margin: float = 0.0  # the query's (service.options.QUERY_POWER_MARGIN); power budgets only

    @property
    def searched_budget(self) -> float:
        """The budget the stored figures were searched under: the budget less the query's margin."""
        return lowered_budget(self.budget, self.error_margin, self.power_margin)


@dataclass(frozen=True)
class FrontierPoint:
    """One point of a frontier with its predictions for the frame rate a query asked for."""

    indices: tuple[int, ...]
    packed: int
    power_w: float
    error: float
    frame_time_s: float | None
    fps: float | None
    meets_fps: bool | None


class _FrontierLists:
    """One tier of a frontier at the frame-rate target ``fps`` as plain lists for :mod:`bisect` (the same
    answers as ``Frontier.under_power`` / ``under_error``, which it defers to when the points are not
    sorted as a tier's must be), with each point's frame time, frame rate reached and whether it meets
    ``fps``. Built for a whole frontier it holds the meeting tier (all points when none meets the target
    or frame times are unknown: ``Frontier.tiers``) and ``slow``, the slow tier's lists (None if none)."""

    __slots__ = ("error", "fps", "fps_reached", "frame_time", "frontier", "meets", "neg_error", "packed",
                 "points", "power", "searched", "slow", "sorted")

    def __init__(self, frontier: Frontier, fps: float, tier: Frontier | None = None) -> None:
        self.frontier = frontier
        self.fps = fps
        self.slow: _FrontierLists | None = None
        if tier is None:
            tier, slow = frontier.tiers(fps)
            if slow is not None:
                self.slow = _FrontierLists(frontier, fps, slow)
        self.searched = searched = tier
        self.power = [float(v) for v in searched.power_w]
        self.error = [float(v) for v in searched.error]
        self.neg_error = [float(v) for v in -searched.error]
        self.packed = [int(v) for v in searched.packed]
        self.sorted = all(a <= b for a, b in itertools.pairwise(self.power)) and all(
            a <= b for a, b in itertools.pairwise(self.neg_error))
        n = len(self.power)
        if searched.frame_time_s is None:
            self.frame_time: list[float | None] = [None] * n
            self.fps_reached: list[float | None] = [None] * n
            self.meets: list[bool | None] = [None] * n
        else:
            self.frame_time = [float(v) for v in searched.frame_time_s]
            self.fps_reached = [frame_rate_reached(t, fps) for t in self.frame_time]  # type: ignore[arg-type]
            self.meets = [meets_frame_rate(t, fps) for t in self.frame_time]  # type: ignore[arg-type]
        self.points: list[FrontierPoint] | None = None  # decoded on first use

    @staticmethod
    def of_tiers(frontier: Frontier, fps: float, fast: Frontier, slow: Frontier | None) -> _FrontierLists:
        """The lists of a frontier's two tiers drawn elsewhere (``slow`` None: one tier)."""
        lists = _FrontierLists(frontier, fps, fast)
        if slow is not None:
            lists.slow = _FrontierLists(frontier, fps, slow)
        return lists

    def within(self, mode: str, budget: float) -> list[int]:
        """Ranks of the points that keep a budget (``mode`` "power": power <= budget, "error": error <=
        budget), in frontier order."""
        values = self.power if mode == "power" else self.error
        return [k for k, v in enumerate(values) if v <= budget]

    def under_power(self, budget: float) -> tuple[int, bool]:
        if not self.sorted:
            return self.searched.under_power(budget)
        i = bisect.bisect_right(self.power, budget) - 1
        return (0, True) if i < 0 else (i, False)

    def under_error(self, budget: float) -> tuple[int, bool]:
        if not self.sorted:
            return self.searched.under_error(budget)
        i = bisect.bisect_left(self.neg_error, -budget)
        return (len(self.power) - 1, True) if i >= len(self.power) else (i, False)


class _FrameTiers:
    """A stored frontier at a frame-rate target ``fps`` whose points' frame times are known at each of
    its pricing cameras (``figures``): what a query needs to draw the tiers of its own frame.

    Each point's frame time at the frame is predicted by the Shepard interpolation of its cameras' frame
    times (:meth:`.priced.PricedFigures.frame_time`); a point whose cameras all keep up with ``fps`` is
    predicted to keep up anywhere between them, one whose cameras all miss it to miss it, so only the
    points whose cameras disagree (``mixed``) are interpolated per query. The frame's tiers are
    :func:`.frontier.frontier_tiers` of the stored points (their stored, worst error and power at
    ``fps``: what budgets are checked against) by that prediction, as a bit mask over the stored points
    (bit ``j``: point ``j`` of the stored frontier is predicted to meet ``fps``). Where the mask is the
    stored frame times' own (``worst_mask``), they are the store's tiers (``stored``, the lists a store
    without per-camera frame times searches); other masks' tiers are drawn on first use and kept."""

    __slots__ = ("error", "figures", "fixed", "fps", "frame_time", "frontier", "masks", "mixed", "packed",
                 "power", "stored", "worst_mask")

    #: masks kept per frontier and rate (a frame's mask changes only where a point's prediction crosses
    #: the frame period: a few per frontier along a path)
    MASKS = 256

    def __init__(self, frontier: Frontier, figures: PricedFigures, fps: float, power: Sequence[float],
                 stored: _FrontierLists) -> None:
        assert frontier.frame_time_s is not None
        self.frontier, self.figures, self.fps, self.stored = frontier, figures, fps, stored
        self.packed = frontier.packed
        self.error = frontier.error
        self.power = np.asarray(power, dtype=np.float64)
        self.frame_time = frontier.frame_time_s
        self.worst_mask = sum(1 << j for j, t in enumerate(self.frame_time.tolist())
                              if meets_frame_rate(t, fps))
        self.fixed = 0  # points whose every camera keeps up
        self.mixed: list[int] = []  # points kept up with at some of their cameras only
        for j in range(len(frontier)):
            lo, hi = figures.frame_time_range(j)
            if meets_frame_rate(hi, fps):
                self.fixed |= 1 << j
            elif meets_frame_rate(lo, fps):
                self.mixed.append(j)
        self.masks: dict[int, _FrontierLists] = {}

    def mask(self, weights: Sequence[float]) -> int:
        """The stored points predicted to keep up with ``fps`` at the frame the ``weights`` weigh the
        pricing cameras for."""
        m = self.fixed
        figures, fps = self.figures, self.fps
        for j in self.mixed:
            if meets_frame_rate(figures.frame_time(weights, j), fps):
                m |= 1 << j
        return m

    def lists(self, mask: int) -> _FrontierLists:
        """The lists of the tiers a frame with ``mask`` searches."""
        if mask == self.worst_mask:
            return self.stored
        lists = self.masks.get(mask)
        if lists is None:
            n = len(self.frontier)
            if mask < 0 or mask >> n:
                raise ValueError("a tier mask names points the frontier does not have")
            meets = [bool((mask >> j) & 1) for j in range(n)]
            fast, slow = frontier_tiers(self.error, self.power, meets)

            def tier(idx: list[int]) -> Frontier:
                k = np.asarray(idx, dtype=np.int64)
                return Frontier(self.packed[k], self.error[k], self.power[k], self.frame_time[k])

            lists = _FrontierLists.of_tiers(self.frontier, self.fps, tier(fast), tier(slow) if slow else None)
            if len(self.masks) >= self.MASKS:
                self.masks.clear()
            self.masks[mask] = lists
        return lists

    def predicted(self, weights: Sequence[float], packed: int) -> tuple[float, float, bool]:
        """(frame time, frame rate reached, whether it keeps up with ``fps``) of stored setting ``packed``
        predicted at the frame the ``weights`` are for."""
        j = self.figures.point(packed)  # the figures list the stored points in frontier order
        if j is None:
            raise ValueError("not a point of this frontier")
        t = self.figures.frame_time(weights, j)
        return t, frame_rate_reached(t, self.fps), meets_frame_rate(t, self.fps)


def _repriced_power(frontier: Frontier, priced_fps: float, fps: float, static_power_w: float) -> list[float]:
    """Each stored point's power (priced for ``priced_fps``) at the frame-rate target ``fps``."""
    assert frontier.frame_time_s is not None
    return [power_at_rate(float(p), float(t), priced_fps, fps, static_power_w)
            for p, t in zip(frontier.power_w, frontier.frame_time_s, strict=True)]


class LookupIndex:
    """Tables derived from a store for fast lookups (built once per store: a store is not changed after
    it is made)."""

    def __init__(self, root_min: np.ndarray, root_size: float, lattice_depth: int, children: np.ndarray,
                 corner_coords: np.ndarray, corner_views: np.ndarray,
                 parameters: Sequence[StoredParameter] = ()) -> None:
        self.lattice_depth = lattice_depth
        self.parameters = tuple(parameters)
        self.views: list[list[int]] = corner_views.tolist()  # frontier id of each (corner, view)
        self.leaf_corners: dict[int, np.ndarray] = {}
        self.node_origin: dict[int, tuple[int, int, int, int]] = {}
        self._walk(children, corner_coords)
        side = 1 << lattice_depth
        cell = root_size / side
        self._lo = tuple(float(c) for c in root_min)
        self._hi = tuple(float(c) + root_size for c in root_min)
        self._lattice_scale = side / root_size
        self._children = [int(c) for c in children]
        # per leaf: its corners' ids and positions (the same floats as root_min + coords * cell)
        self.leaf_corner_pos: dict[int, list[tuple[int, tuple[float, float, float]]]] = {
            leaf: [(int(c), tuple(float(v) for v in root_min + corner_coords[c] * cell))  # type: ignore[misc]
                   for c in ids]
            for leaf, ids in self.leaf_corners.items()}
        self._frustum_cache: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}
        self._last_frustum: tuple[float, float, tuple[np.ndarray, np.ndarray]] | None = None
        self._frontiers: dict[int, _FrontierLists] = {}
        self._other_rates: dict[tuple[int, float], _FrontierLists] = {}
        self._frame_tiers: dict[tuple[int, float], _FrameTiers] = {}
        self._decoded: dict[int, tuple[tuple[int, ...], dict[str, Any], bool]] = {}

    def _walk(self, children: np.ndarray, corner_coords: np.ndarray) -> None:
        """Each node's lattice origin and size, each leaf's eight corner ids (child order)."""
        key = {tuple(int(c) for c in xyz): i for i, xyz in enumerate(corner_coords)}
        stack = [(0, 0, 0, 0, 1 << self.lattice_depth)]
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

    def leaf_depths(self, children: np.ndarray) -> dict[int, int]:
        """Depth of every leaf (root = 0)."""
        side = 1 << self.lattice_depth
        return {n: round(math.log2(side / o[3])) for n, o in self.node_origin.items() if children[n] == -1}

    # -- the query's steps --------------------------------------------------------------------------

    def find_leaf(self, position: Any) -> tuple[int, tuple[float, float, float], bool]:
        """Leaf containing ``position`` (clamped into the root): (leaf, clamped position, clamped)."""
        px, py, pz = camera.vec3(position, "position")
        (lx, ly, lz), (hx, hy, hz) = self._lo, self._hi
        qx, qy, qz = min(max(px, lx), hx), min(max(py, ly), hy), min(max(pz, lz), hz)
        clamped = (qx, qy, qz) != (px, py, pz)
        k = self._lattice_scale
        ux, uy, uz = (qx - lx) * k, (qy - ly) * k, (qz - lz) * k
        node = 0
        x = y = z = 0
        s = 1 << self.lattice_depth
        children = self._children
        while children[node] != -1:
            h = s // 2
            i = (ux >= x + h) | ((uy >= y + h) << 1) | ((uz >= z + h) << 2)
            x += h * (i & 1)
            y += h * ((i >> 1) & 1)
            z += h * ((i >> 2) & 1)
            s = h
            node = children[node] + i
        return node, (qx, qy, qz), clamped

    def frustum(self, vfov: float, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        """The frustum rays and weights of a field of view, kept per (vfov, aspect) to 6 decimals (the
        first camera with those rounded values sets them)."""
        last = self._last_frustum
        if last is not None and last[0] == vfov and last[1] == aspect:
            return last[2]
        key = (round(vfov, 6), round(aspect, 6))
        rays = self._frustum_cache.get(key)
        if rays is None:
            rays = camera.frustum_rays(vfov, aspect)
            if len(self._frustum_cache) > 64:
                self._frustum_cache.clear()
            self._frustum_cache[key] = rays
        self._last_frustum = (vfov, aspect, rays)
        return rays

    def choose_view(self, rotation: Any, vfov: float, aspect: float) -> int:
        """View-cube face that receives the largest part of the camera frustum."""
        rays, weights = self.frustum(vfov, aspect)
        return camera.frustum_face(np.asarray(rotation, dtype=np.float64).reshape(3, 3), rays, weights)

    def locate(self, position: Any, rotation: Any, vfov: float, aspect: float) -> tuple[int, int, int, bool]:
        """(leaf, corner, view, clamped) a camera looks up: nearest corner of its leaf, then the face."""
        leaf, q, clamped = self.find_leaf(position)
        return leaf, self.nearest_corner(leaf, q), self.choose_view(rotation, vfov, aspect), clamped

    def nearest_corner(self, leaf: int, q: tuple[float, float, float]) -> int:
        """The leaf corner nearest to ``q`` (the first in child order among equally near ones).

        The nearest corner of a cube is the one on ``q``'s side of the middle along each axis; only when
        ``q`` is (within rounding) on a middle plane are the eight distances compared."""
        corners = self.leaf_corner_pos[leaf]
        qx, qy, qz = q
        (x0, y0, z0), (x1, y1, z1) = corners[0][1], corners[7][1]
        dx0, dx1 = (x0 - qx) ** 2, (x1 - qx) ** 2
        dy0, dy1 = (y0 - qy) ** 2, (y1 - qy) ** 2
        dz0, dz1 = (z0 - qz) ** 2, (z1 - qz) ** 2
        tie = 1e-12 * (dx0 + dx1 + dy0 + dy1 + dz0 + dz1)
        if abs(dx1 - dx0) > tie and abs(dy1 - dy0) > tie and abs(dz1 - dz0) > tie:
            return corners[(dx1 < dx0) | ((dy1 < dy0) << 1) | ((dz1 < dz0) << 2)][0]
        best = math.inf
        corner = -1
        for c, (cx, cy, cz) in corners:
            dd = (cx - qx) ** 2 + (cy - qy) ** 2 + (cz - qz) ** 2
            if dd < best:
                best, corner = dd, c
        return corner

    def frontier_lists(self, frontier_id: int, frontier: Frontier, fps: float) -> _FrontierLists:
        """The lists of a stored frontier at the store's own rate ``fps``."""
        lists = self._frontiers.get(frontier_id)
        if lists is None or lists.frontier is not frontier or lists.fps != fps:
            lists = self._frontiers[frontier_id] = _FrontierLists(frontier, fps)
        return lists

    def frontier_lists_at(self, frontier_id: int, frontier: Frontier, priced_fps: float, fps: float,
                          static_power_w: float) -> _FrontierLists:
        """The lists of a stored frontier (priced for ``priced_fps``) repriced for another rate ``fps``
        and pruned again (kept per (frontier, fps); a few rates at a time)."""
        key = (frontier_id, fps)
        lists = self._other_rates.get(key)
        if lists is None or lists.frontier is not frontier:
            if len(self._other_rates) > 4096:
                self._other_rates.clear()
            assert frontier.frame_time_s is not None
            power = _repriced_power(frontier, priced_fps, fps, static_power_w)
            repriced = Frontier.from_points(frontier.packed.tolist(), frontier.error.tolist(), power,
                                            frontier.frame_time_s.tolist(), fps)
            lists = _FrontierLists(repriced, fps)
            lists.frontier = frontier  # the stored frontier it was derived from (the cache's check)
            self._other_rates[key] = lists
        return lists

    def frame_tiers(self, frontier_id: int, frontier: Frontier, figures: PricedFigures, priced_fps: float,
                    fps: float, static_power_w: float | None) -> _FrameTiers:
        """What a query at the frame-rate target ``fps`` needs to draw its frame's tiers of a stored
        frontier (priced for ``priced_fps``) whose per-camera frame times are known (kept per (frontier,
        fps), as the lists are)."""
        key = (frontier_id, fps)
        plan = self._frame_tiers.get(key)
        if plan is None or plan.frontier is not frontier or plan.figures is not figures:
            if len(self._frame_tiers) > 4096:
                self._frame_tiers.clear()
            if fps == priced_fps:
                stored = self.frontier_lists(frontier_id, frontier, fps)
                power = frontier.power_w
            else:
                assert frontier.frame_time_s is not None and static_power_w is not None
                stored = self.frontier_lists_at(frontier_id, frontier, priced_fps, fps, static_power_w)
                power = _repriced_power(frontier, priced_fps, fps, static_power_w)
            plan = self._frame_tiers[key] = _FrameTiers(frontier, figures, fps, power, stored)
        return plan

    def lists_of(self, hit: LookupResult) -> _FrontierLists:
        """The lists of the tier ``hit`` was chosen from (its frontier at the rate it was asked for, with
        the tiers of ``hit``'s own frame where they are drawn per frame (``hit.meeting``): the slow tier
        for a point that misses the rate while the frontier has meeting points)."""
        if hit.meeting >= 0:
            plan = self._frame_tiers.get((hit.frontier, hit.fps_target))  # type: ignore[arg-type]
            if plan is None:
                raise ValueError("the lookup result's frontier is no longer cached: look the camera up again")
            lists = plan.lists(hit.meeting)
        else:
            lists = self._frontiers.get(hit.frontier)  # type: ignore[assignment]
            if lists is None or lists.fps != hit.fps_target:
                lists = self._other_rates.get((hit.frontier, hit.fps_target))  # type: ignore[assignment]
            if lists is None:
                raise ValueError("the lookup result's frontier is no longer cached: look the camera up again")
        if lists.slow is not None and hit.meets_fps is False:
            return lists.slow
        return lists

    def budget_points(self, hit: LookupResult) -> list[FrontierPoint]:
        """The points of the tier ``hit`` came from (its frontier at its frame-rate target: the meeting
        tier, or the slow tier when ``hit`` misses the target under the ``"budget"`` priority; the tiers
        of ``hit``'s own frame where they are drawn per frame) that keep its budget, in frontier order
        (power ascending); only ``hit``'s own point when none does (``hit.infeasible``). Where the tiers
        are drawn per frame, each point's frame time, frame rate and ``meets_fps`` are its prediction
        at ``hit``'s camera (``hit.weights``)."""
        lists = self.lists_of(hit)
        ranks = [hit.rank] if hit.infeasible else lists.within(hit.budget_mode, hit.searched_budget)
        if hit.meeting >= 0:  # each point's prediction at the hit's camera
            plan = self._frame_tiers[(hit.frontier, hit.fps_target)]  # type: ignore[index]
            return [FrontierPoint(self.decoded(pk)[0], pk, lists.power[k], lists.error[k],
                                  *plan.predicted(hit.weights, pk))
                    for k in ranks for pk in (lists.packed[k],)]
        if lists.points is None:
            lists.points = [FrontierPoint(self.decoded(pk)[0], pk, lists.power[k], lists.error[k],
                                          lists.frame_time[k], lists.fps_reached[k], lists.meets[k])
                            for k, pk in enumerate(lists.packed)]
        return [lists.points[k] for k in ranks]

    def decoded(self, packed: int) -> tuple[tuple[int, ...], dict[str, Any]]:
        """Value indices and a fresh ``{name: value}`` of a packed setting (decoded once per setting;
        callers may change the dict they get)."""
        hit = self._decoded.get(packed)
        if hit is None:
            indices = unpack_indices(packed, len(self.parameters))
            settings = settings_of(self.parameters, indices)
            shared = not any(isinstance(v, list) for v in settings.values())  # lists are made afresh
            hit = self._decoded[packed] = (indices, settings, shared)
        indices, settings, shared = hit
        return indices, dict(settings) if shared else settings_of(self.parameters, indices)
