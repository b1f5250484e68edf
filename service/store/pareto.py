"""The runtime Pareto store: an octree over the camera path with one Pareto frontier per (corner, view).

The service writes stores, the Blender add-on reads them during playback; the document is described in
:mod:`service.store.format`, the lookup in :mod:`service.store.lookup`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..options import QUERY_ERROR_MARGIN, QUERY_FPS, QUERY_POWER_MARGIN, QUERY_PRIORITY
from . import camera, codec, format
from .camera import VIEW_FORWARD, VIEW_UP, view_up
from .figures import FiguresSize
from .frame_rate import power_at_rate
from .frontier import Frontier
from .lookup import FrontierPoint, LookupIndex, LookupResult, lowered_budget
from .packing import MAX_PARAMS, MAX_VALUES_PER_PARAM, StoredParameter, settings_of
from .priced import PricedFigures


def _finite_vec3(v: Any, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a


@dataclass
class ParetoStore:
    """Octree of camera samples with one Pareto frontier per (corner, view); see
    :mod:`service.store.format` for what each field holds."""

    parameters: tuple[StoredParameter, ...]
    root_min: np.ndarray
    root_size: float
    lattice_depth: int
    children: np.ndarray  # int32 (n_nodes,)
    corner_coords: np.ndarray  # int64 (C, 3) lattice coordinates
    corner_views: np.ndarray  # int64 (C, 6) frontier ids
    frontiers: list[Frontier]
    vfov: float = 0.6911
    aspect: float = 16 / 9
    profile: str = "mobile"
    fps: float = 30.0
    meta: dict[str, Any] = field(default_factory=dict)
    view_dirs: np.ndarray | None = None  # float64 (C, 6, 3) sample directions; None = the axes
    frontier_dirs: np.ndarray | None = None  # float64 (F, 3) sample direction of each frontier
    frontier_eyes: np.ndarray | None = None  # float64 (F, 3) sample eye of each frontier
    #: per frontier, its points' figures at each camera it was priced at (None: the stored figures only)
    priced: list[PricedFigures | None] | None = None

    def __post_init__(self) -> None:
        self.root_min = _finite_vec3(self.root_min, "root_min")
        self.root_size = float(self.root_size)
        if not (math.isfinite(self.root_size) and self.root_size > 0):
            raise ValueError("root_size must be positive and finite")
        if not 0 <= self.lattice_depth <= 16:
            raise ValueError("lattice_depth must be in 0..16")
        self.fps = float(self.fps)
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValueError("fps must be positive and finite")
        if len({f.frame_time_s is None for f in self.frontiers}) > 1:
            raise ValueError("frame times must be known for every frontier or for none")
        self.children = np.asarray(self.children, dtype=np.int64).reshape(-1)
        self.corner_coords = np.asarray(self.corner_coords, dtype=np.int64).reshape(-1, 3)
        self.corner_views = np.asarray(self.corner_views, dtype=np.int64).reshape(-1, 6)
        self._check_tree()
        self._check_sample_cameras()
        self._check_priced()
        if len(self.parameters) > MAX_PARAMS:
            raise ValueError(f"at most {MAX_PARAMS} parameters")
        for prm in self.parameters:
            if len(prm.values) > MAX_VALUES_PER_PARAM:
                raise ValueError(f"parameter {prm.name!r} has more than 16 values")
        FiguresSize.from_meta(self.meta)  # (a bad size is refused on reading, not at the first label)
        self._index = LookupIndex(self.root_min, self.root_size, self.lattice_depth, self.children,
                                  self.corner_coords, self.corner_views, self.parameters)

    def _check_tree(self) -> None:
        n_nodes = self.children.size
        if n_nodes == 0:
            raise ValueError("a store needs at least the root node")
        ch = self.children
        if np.any((ch != -1) & ((ch <= 0) | (ch + 8 > n_nodes))):
            raise ValueError("children index out of range")
        if self.corner_coords.shape[0] != self.corner_views.shape[0]:
            raise ValueError("corner_coords and corner_views disagree on the corner count")
        side = 1 << self.lattice_depth
        if self.corner_coords.size and (self.corner_coords.min() < 0 or self.corner_coords.max() > side):
            raise ValueError("corner lattice coordinates out of range")
        if self.corner_views.size and (
            self.corner_views.min() < 0 or self.corner_views.max() >= len(self.frontiers)
        ):
            raise ValueError("corner view refers to a missing frontier")

    def _check_sample_cameras(self) -> None:
        if self.view_dirs is not None:
            vd = np.asarray(self.view_dirs, dtype=np.float64)
            if vd.shape != (self.corner_coords.shape[0], 6, 3) or not np.all(np.isfinite(vd)):
                raise ValueError("view_dirs must be finite (corners, 6, 3)")
            n = np.linalg.norm(vd, axis=2, keepdims=True)
            if np.any(n < 1e-9):
                raise ValueError("view_dirs must be non-zero")
            self.view_dirs = vd / n
        if (self.frontier_dirs is None) != (self.frontier_eyes is None):
            raise ValueError("frontier_dirs and frontier_eyes come together")
        if self.frontier_dirs is not None:
            fd = np.asarray(self.frontier_dirs, dtype=np.float64)
            fe = np.asarray(self.frontier_eyes, dtype=np.float64)
            nf = len(self.frontiers)
            if fd.shape != (nf, 3) or fe.shape != (nf, 3) or not (np.all(np.isfinite(fd))
                                                                   and np.all(np.isfinite(fe))):
                raise ValueError("frontier_dirs and frontier_eyes must be finite (frontiers, 3)")
            n = np.linalg.norm(fd, axis=1, keepdims=True)
            if np.any(n < 1e-9):
                raise ValueError("frontier_dirs must be non-zero")
            self.frontier_dirs = fd / n
            self.frontier_eyes = fe

    def _check_priced(self) -> None:
        if self.priced is None:
            return
        self.priced = list(self.priced)
        if len(self.priced) != len(self.frontiers):
            raise ValueError("priced figures must be given for every frontier (None where there are none)")
        for pf, fr in zip(self.priced, self.frontiers, strict=True):
            if pf is None:
                continue
            if not isinstance(pf, PricedFigures):
                raise ValueError("priced figures must be PricedFigures or None")
            if pf.packed.size != len(fr) or np.any(pf.packed != fr.packed.astype(np.int64)):
                raise ValueError("priced figures must list their frontier's points in frontier order")
        if all(pf is None for pf in self.priced):
            self.priced = None
            return
        if len({pf.frame_times_known for pf in self.priced if pf is not None}) > 1:
            raise ValueError("per-camera frame times must be kept for every priced frontier or for none")
        if self.priced_frame_times_known and not self.frame_times_known:
            raise ValueError("per-camera frame times need the frontiers' frame times")

    # -- what is stored ---------------------------------------------------------------------------

    @property
    def n_params(self) -> int:
        return len(self.parameters)

    @property
    def frame_times_known(self) -> bool:
        """Whether the frontiers record frame times (stores of format 4 on; older ones do not)."""
        return bool(self.frontiers) and self.frontiers[0].frame_time_s is not None

    @property
    def priced_frame_times_known(self) -> bool:
        """Whether the per-camera figures include each point's frame time at each pricing camera (the
        lookup then draws each frame's tiers from their prediction at its camera: :mod:`.lookup`)."""
        return self.priced is not None and any(pf is not None and pf.frame_times_known for pf in self.priced)

    def corner_positions(self) -> np.ndarray:
        """World positions (C, 3) of the corners."""
        cell = self.root_size / (1 << self.lattice_depth)
        return self.root_min[None, :] + self.corner_coords.astype(np.float64) * cell

    def sample_direction(self, corner: int, view: int) -> np.ndarray:
        """Unit direction (world) at which the (corner, view) frontier was measured."""
        if self.frontier_dirs is not None:
            return self.frontier_dirs[int(self.corner_views[int(corner), int(view)])].copy()
        if self.view_dirs is None:
            return VIEW_FORWARD[int(view)].copy()
        return self.view_dirs[int(corner), int(view)].copy()

    def sample_camera(self, corner: int, view: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(eye, forward, up) of the camera sample behind the (corner, view) frontier."""
        f = self.sample_direction(corner, view)
        if self.frontier_eyes is not None:
            return self.frontier_eyes[int(self.corner_views[int(corner), int(view)])].copy(), f, view_up(f)
        up = VIEW_UP[int(view)].copy() if self.view_dirs is None else view_up(f)
        return self.corner_positions()[int(corner)], f, up

    def frontier(self, corner: int, view: int) -> Frontier:
        return self.frontiers[int(self.corner_views[corner, view])]

    def leaf_depths(self) -> dict[int, int]:
        """Depth of every leaf (root = 0)."""
        return self._index.leaf_depths(self.children)

    def leaf_corners(self, leaf: int) -> np.ndarray:
        """The eight corner ids of a leaf, in child order (bit 0: +x, bit 1: +y, bit 2: +z)."""
        return self._index.leaf_corners[int(leaf)].copy()

    def settings_of(self, indices: Sequence[int]) -> dict[str, Any]:
        """Parameter name -> value for value indices (JSON-friendly values)."""
        return settings_of(self.parameters, indices)

    # -- lookup -----------------------------------------------------------------------------------

    def find_leaf(self, position: Any) -> tuple[int, np.ndarray, bool]:
        """Leaf containing ``position`` (clamped into the root); returns (leaf, clamped position, clamped)."""
        leaf, q, clamped = self._index.find_leaf(position)
        return leaf, np.asarray(q), clamped

    def choose_view(self, rotation: np.ndarray, vfov: float, aspect: float) -> int:
        """View-cube face that receives the largest (solid-angle weighted) part of the camera frustum."""
        return self._index.choose_view(rotation, vfov, aspect)

    def locate(self, position: Any, direction: Any = None, matrix: Any = None, fov: float | None = None,
               aspect: float | None = None, up: Any = None) -> tuple[int, int]:
        """(corner, view) whose frontier :meth:`lookup` would read for this camera (no budget needed);
        the optimiser uses it to group path frames by the sample that will serve them."""
        rot = camera.rotation_floats(direction, matrix, up)
        vf = self.vfov if fov is None else float(fov)
        asp = self.aspect if aspect is None else float(aspect)
        _, corner, view, _ = self._index.locate(position, rot, vf, asp)
        return corner, view

    @property
    def figures(self) -> FiguresSize:
        """Where the store's error, power and frame-time figures were measured (the display size they hold
        for, or the search's preview size): what every shown figure is labelled with."""
        return FiguresSize.from_meta(self.meta)

    @property
    def static_power_w(self) -> float | None:
        """The profile's static power the store's figures include (``meta``; None: not recorded, stores
        made before queries could ask for another frame rate)."""
        v = self.meta.get("static_power_w")
        return None if v is None else float(v)

    def check_fps(self, fps: float | None) -> float:
        """The frame-rate target of a query: the store's ``fps`` when ``fps`` is None, else ``fps``
        validated (:data:`service.options.QUERY_FPS`) and usable with this store (another rate needs
        frame times and the static power)."""
        if fps is None:
            return self.fps
        rate = float(QUERY_FPS.check(fps))
        if rate == self.fps:
            return rate
        if not self.frame_times_known:
            raise ValueError(f"this store predates frame times: it can only answer for its own "
                             f"{self.fps:g} fps")
        if self.static_power_w is None:
            raise ValueError(f"this store does not record the static power its figures include: it can "
                             f"only answer for its own {self.fps:g} fps (optimise it again)")
        return rate

    def lookup(self, position: Any, direction: Any = None, matrix: Any = None, fov: float | None = None,
               power_budget: float | None = None, error_budget: float | None = None,
               aspect: float | None = None, up: Any = None, fps: float | None = None,
               priority: str = "frame_rate", error_margin: float = 0.0,
               power_margin: float = 0.0) -> LookupResult:
        """Settings for a camera at ``position`` looking along ``direction`` (or oriented by ``matrix``,
        Blender's 4x4 camera world matrix) with vertical field of view ``fov`` in radians, under exactly
        one of ``power_budget`` (W) or ``error_budget`` (1 - SSIM), for the frame-rate target ``fps``
        (default: the store's; power is predicted at the frame rate reached for it). ``priority``
        (:data:`service.options.QUERY_PRIORITY`): ``"frame_rate"`` chooses among the settings that keep
        up with the target when the store knows frame times and any does; ``"budget"`` chooses among
        them while one of them keeps the budget, else among the stored settings that miss the target
        but keep the budget (``LookupResult.meets_fps`` False; :mod:`service.store.lookup`).
        ``error_margin`` (:data:`service.options.QUERY_ERROR_MARGIN`): an error budget is searched that much
        lower (``LookupResult.searched_budget``; ``infeasible`` says nothing lies under it);
        ``power_margin`` (:data:`service.options.QUERY_POWER_MARGIN`): a power budget is searched that
        fraction lower, likewise."""
        if (power_budget is None) == (error_budget is None):
            raise ValueError("give exactly one of power_budget or error_budget")
        budget = float(power_budget if power_budget is not None else error_budget)  # type: ignore[arg-type]
        if not math.isfinite(budget):
            raise ValueError("budget must be finite")
        if priority != "frame_rate":
            QUERY_PRIORITY.check(priority)
        e_margin = float(QUERY_ERROR_MARGIN.check(error_margin)) if error_margin else 0.0
        p_margin = float(QUERY_POWER_MARGIN.check(power_margin)) if power_margin else 0.0
        if error_budget is None:
            e_margin = 0.0
        else:
            p_margin = 0.0
        searched = lowered_budget(budget, e_margin, p_margin)
        rate = self.check_fps(fps)
        index = self._index
        rot = camera.rotation_floats(direction, matrix, up)
        vf = camera.check_fov(self.vfov if fov is None else fov)
        asp = camera.check_aspect(self.aspect if aspect is None else aspect)
        leaf, corner, view, clamped = index.locate(position, rot, vf, asp)
        fid = index.views[corner][view]
        figures = None if self.priced is None else self.priced[fid]
        weights: tuple[float, ...] = ()
        if figures is not None:
            forward = (-rot[2], -rot[5], -rot[8])  # the camera looks down its local -Z
            weights = figures.weights(position, forward)  # (checked finite by the leaf search)
        plan = None
        meeting = -1
        if figures is not None and figures.frame_times_known:  # this frame's tiers, from its prediction
            plan = index.frame_tiers(fid, self.frontiers[fid], figures, self.fps, rate, self.static_power_w)
            meeting = plan.mask(weights)
            fr = plan.lists(meeting)
        elif rate == self.fps:
            fr = index.frontier_lists(fid, self.frontiers[fid], rate)
        else:
            fr = index.frontier_lists_at(fid, self.frontiers[fid], self.fps, rate,
                                         self.static_power_w)  # type: ignore[arg-type]
        if power_budget is not None:
            i, infeasible = fr.under_power(searched)
        else:
            i, infeasible = fr.under_error(searched)
        if infeasible and fr.slow is not None and priority == "budget":
            slow = fr.slow
            j, missed = slow.under_power(searched) if power_budget is not None else slow.under_error(searched)
            if not missed:  # only settings that miss the frame rate keep the budget
                fr, i, infeasible = slow, j, False
        packed = fr.packed[i]
        indices, settings = index.decoded(packed)
        error, power = fr.error[i], fr.power[i]
        frame_time, reached, meets = fr.frame_time[i], fr.fps_reached[i], fr.meets[i]
        if plan is not None:  # the frame's prediction, which its tiers were drawn from
            frame_time, reached, meets = plan.predicted(weights, packed)
        if figures is not None:
            error, power = self._expected(figures, weights, packed, error, power, fr.frame_time[i], rate)
        return LookupResult(indices, packed, settings, fr.power[i], fr.error[i], clamped, infeasible,
                            corner, view, leaf, frame_time, reached, meets, rate,
                            fid, i, "power" if power_budget is not None else "error", budget, priority,
                            error, power, weights, meeting, e_margin, p_margin)

    def _expected(self, figures: PricedFigures, weights: Sequence[float], packed: int, error: float,
                  power: float, frame_time_s: float | None, rate: float) -> tuple[float, float]:
        """(error, power) of ``packed`` interpolated at a camera (``weights``), its power at the frame
        rate ``rate`` asked for (each camera's repriced with its own frame time where those are kept,
        else the interpolated power with ``frame_time_s``, the stored one); ``error`` and ``power`` (the
        stored figures) when the frontier has no figures for it."""
        static = self.static_power_w
        other = rate != self.fps and static is not None
        if other and figures.frame_times_known:
            def reprice(p: float, t: float) -> float:
                return power_at_rate(p, t, self.fps, rate, static)  # type: ignore[arg-type]

            got = figures.expected(weights, packed, reprice)
            return (error, power) if got is None else got
        got = figures.expected(weights, packed)
        if got is None:
            return error, power
        e, p = got
        if other and frame_time_s is not None:
            p = power_at_rate(p, frame_time_s, self.fps, rate, static)  # type: ignore[arg-type]
        return e, p

    def expected(self, hit: LookupResult, point: FrontierPoint) -> tuple[float, float]:
        """The predicted (error, power) of ``point`` (one of :meth:`budget_points` of ``hit``, or ``hit``'s
        own) at ``hit``'s camera and frame-rate target: its figures at the frontier's pricing cameras
        interpolated at that camera (:mod:`.priced`), else its stored figures."""
        figures = None if self.priced is None or hit.frontier < 0 else self.priced[hit.frontier]
        if figures is None or not hit.weights:
            return point.error, point.power_w
        rate = self.fps if hit.fps_target is None else hit.fps_target
        # (a point's frame time is its stored one unless the frontier keeps per-camera frame times, and
        # then each camera's own reprices its power)
        return self._expected(figures, hit.weights, point.packed, point.error, point.power_w,
                              point.frame_time_s, rate)

    def budget_points(self, hit: LookupResult) -> list[FrontierPoint]:
        """The points of the tier ``hit`` came from that keep its budget (power ascending), with their
        predictions at ``hit``'s frame-rate target: the settings the temporal filter may show on that
        frame (``hit``'s own point alone when nothing keeps the budget). Under the ``"budget"`` priority
        a hit that misses the target allows the slow tier's points within the budget (none of the
        meeting points keeps it then); otherwise the meeting points within the budget, as under
        ``"frame_rate"``."""
        return self._index.budget_points(hit)

    # -- serialisation ----------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The versioned JSON document (:mod:`service.store.format`)."""
        return format.to_dict(self)

    def to_json(self) -> str:
        return format.to_json(self)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> ParetoStore:
        return ParetoStore._build(format.fields_from_dict(d))

    @staticmethod
    def from_json(text: str | bytes) -> ParetoStore:
        return ParetoStore._build(format.fields_from_json(text))

    @staticmethod
    def _build(fields: dict[str, Any]) -> ParetoStore:
        try:
            return ParetoStore(**fields)
        except (KeyError, TypeError) as exc:
            raise ValueError(f"malformed store: missing or wrong field {exc}") from exc

    def stats(self) -> dict[str, Any]:
        """Sizes and counts worth reporting (bytes of the JSON, nodes, corners, views, points)."""
        depths = self.leaf_depths()
        return {
            "size_bytes": len(self.to_json().encode()),
            "nodes": int(self.children.size),
            "leaves": len(depths),
            "depth": max(depths.values()) if depths else 0,
            "corners": int(self.corner_coords.shape[0]),
            "views": int(self.corner_coords.shape[0] * 6),
            "unique_frontiers": len(self.frontiers),
            "frontier_points": int(sum(len(f) for f in self.frontiers)),
            "error_step": 1.0 / codec.QMAX,
            "power_step_w": (max((float(f.power_w.max()) for f in self.frontiers), default=1.0)) / codec.QMAX,
            "frame_times_known": self.frame_times_known,
        }
