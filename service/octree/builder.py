"""The octree builder: the lattice (:mod:`.lattice`), the lock-step search scheduler (:mod:`.search`)
and one camera-sampling strategy (:class:`CameraSampling`: the paper's view cubes, :mod:`.view_cubes`,
or the path's own cameras, :mod:`.path_samples`) put together into a runtime store."""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from service import options
from service.display_pricing import DisplayPricer
from service.evaluation import CameraSpec, Evaluator
from service.nsga import NSGAConfig
from service.params import Indices, ParameterSpace
from service.store import Frontier, ParetoStore, frontier_tiers, meets_frame_rate, split_by_rate
from service.store.priced import PricedFigures

from . import bridge
from .lattice import Lattice, root_cube
from .path_samples import PathSampling, PerCamera
from .search import Progress, Search
from .view_cubes import ViewCubeSampling


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
    # "path" sampling with guard frames: then the frames farther than this from every pricing camera too,
    # at most guard_frames more (0: none)
    guard_radius: float = 0.01
    path_stride: int = 4  # "path" sampling: a full search at every path_stride-th sample along the path
    warm_generations: int = 5  # "path" sampling: generations of the warm-started searches in between
    # the path's resolution, where every recorded point is priced again (None: the search's figures)
    display: tuple[int, int] | None = None
    # at most this many points of each frontier's meeting tier, and of its slow tier (None: as many),
    # priced there (0: all; spread_points)
    display_points: int = 0
    slow_points: int | None = None
    # at most this many more settings of each frontier priced there where the priced meeting tier's
    # errors jump (:mod:`.bridge`; 0: none)
    bridge_points: int = 0
    # steps of the search's descent from max quality toward the frame rate (:meth:`.search.Search.descend`)
    descent_steps: int = 0

    def __post_init__(self) -> None:
        options.check({name: getattr(self, name) for name in (
            "threshold_power_w", "threshold_error", "max_depth", "min_depth", "margin", "view_sampling",
            "path_resolution", "guard_frames", "guard_radius")})


@dataclass
class PathFrames:
    """The camera path as the strategies read it: positions (N, 3), forward vectors and the points
    their central rays see (aimed and path sampling), world matrices, vfovs and aspects (path
    sampling)."""

    positions: np.ndarray
    forwards: np.ndarray | None = None
    targets: np.ndarray | None = None
    matrices: np.ndarray | None = None
    vfovs: np.ndarray | None = None
    aspects: np.ndarray | None = None


class CameraSampling(Protocol):
    """Where the camera samples go and which frontier each (corner, view) gets."""

    def build(self) -> None:
        """Grow the lattice and give every (corner, view) a frontier (measured or inherited)."""

    def store_cameras(self, used: list[int]) -> dict[str, Any]:
        """The store fields saying where the frontiers ``used`` (lattice frontier ids, in store
        order) were measured (``view_dirs`` or ``frontier_dirs`` / ``frontier_eyes``), if any."""

    def pricing_cameras(self) -> dict[int, list[CameraSpec]]:
        """Every measured frontier (lattice frontier id) with the cameras its points are priced at
        (its sample first; a frontier keeps each point's worst figures over them)."""

    def priced_figures(self) -> dict[int, PerCamera]:
        """Per-camera figures of the frontiers the strategy priced at several cameras itself (path
        samples' guards when there is no display pricing; the display pricing replaces them): lattice
        frontier id -> (cameras, sample first; settings; error, power and frame time (K, n))."""

    def pricing_scales(self) -> dict[int, float]:
        """The distance unit of the camera dissimilarity (:func:`service.store.priced.
        camera_dissimilarity`) of every frontier priced at several cameras (lattice frontier id: the
        median viewing distance of the frames it serves); empty when every frontier has one camera."""

    def pricing_plan(self) -> list[tuple[int, int]] | None:
        """While the search runs, the frontiers :meth:`pricing_cameras` will give once it is done, as far
        as the strategy already knows them: (lattice frontier id, or -1 while not measured yet; the
        number of cameras it will be priced at) each. None when they are not known before the search
        ends (the builder then guesses them from the views planned:
        :meth:`OctreeBuilder._pricing_to_come`)."""


def _spread(points: list[tuple[Any, ...]], k: int) -> list[tuple[Any, ...]]:
    """At most ``k`` points of one tier: both ends (the least error and the cheapest) and between them
    the points nearest to even steps along the tier's curve, measured with error and power each scaled
    to their range in the tier.

    Even steps by rank crowd the picks where the search found most points: the cheap end, where many
    settings differ in error but all draw about the static power. On the `desktop` profile's chess a
    median 5 of 7 picks lay above error 0.03, and 26 of 49 frontiers priced nothing with error between
    0.0005 and 0.02 (4 of 49 along the curve), so an error budget of 0.02 fell back to max quality.
    Steps along the curve put picks where power changes too."""
    if len(points) <= k:
        return list(points)
    order = sorted(range(len(points)), key=lambda i: (points[i][1], -points[i][2]))
    if k == 1:
        return [points[order[0]]]
    err = np.array([points[i][1] for i in order], dtype=np.float64)
    pwr = np.array([points[i][2] for i in order], dtype=np.float64)
    span_e, span_p = np.ptp(err), np.ptp(pwr)
    steps = np.hypot(np.diff(err) / span_e if span_e > 0 else 0.0,
                     np.diff(pwr) / span_p if span_p > 0 else 0.0)
    along = np.concatenate(([0.0], np.cumsum(steps)))
    if along[-1] <= 0.0:  # every point at the same figures: by rank
        along = np.arange(len(order), dtype=np.float64)
    free = np.ones(len(order), dtype=bool)
    picks = [0, len(order) - 1]
    free[picks] = False
    for target in along[-1] * np.arange(1, k - 1) / (k - 1):
        gap = np.where(free, np.abs(along - target), np.inf)
        j = int(np.argmin(gap))  # the nearest point not yet picked (more points than k: one is left)
        free[j] = False
        picks.append(j)
    return [points[order[j]] for j in sorted(picks, key=lambda j: order[j])]


def spread_points(points: list[tuple[Any, ...]], k: int, fps: float | None = None,
                  k_slow: int | None = None) -> list[tuple[Any, ...]]:
    """The points of a frontier ((indices, error, power, frame time)) priced at display resolution: at
    most ``k`` of the meeting tier and ``k_slow`` (default ``k``) of the slow tier
    (:func:`service.store.split_by_rate` at ``fps``: the points that meet it, then those that miss it
    while others meet it; 0: all of a tier), each spread along its tier (both ends, the least error and
    the cheapest, when its count is >= 2, and evenly along the tier's curve between them:
    :func:`_spread`). Without ``fps`` (or when no point meets it) one tier, of at most ``k``.

    The slow tier is read only when a lookup's priority is the budget: there it is where an error budget
    that no real-time setting keeps is kept, and the lookup can only pick what was priced. With its two
    ends alone it offered Max and the cheapest slow point, so wherever the cheapest was over the budget
    the lookup picked Max, far below the budget and at Max's frame rate; spread as finely as the meeting
    tier, an error budget finds a slow point about as close to it in either tier. Cost: the slow points
    are near-Max settings, each about as costly to price as the reference render (on the teapot's demo
    store they were a fifth of the pricing's CPU time, bench/RESULTS.md), except Max itself, whose
    figures the reference render gives: with ``k_slow`` 1 (Max alone, the tier's least-error end) the
    slow tier costs nothing, for stores looked up frame rate first."""
    k_slow = k if k_slow is None else k_slow
    if k <= 0 and k_slow <= 0:
        return list(points)
    fast, slow = split_by_rate(points, fps)
    return ((list(fast) if k <= 0 else _spread(fast, k))
            + (list(slow) if k_slow <= 0 else _spread(slow, k_slow)))


#: A frontier whose most accurate real-time point priced has an error over this prices the search's
#: probes that kept up (:meth:`OctreeBuilder._probes_to_price`): the error budget the add-on and the demo
#: start from (issue 7's), which the store would otherwise not keep in real time there. A tighter budget
#: does not get them where the real-time points priced are between it and this.
PROBE_ERROR = 0.02


def kept_up_to_price(points: list[tuple[Any, ...]], kept_up: Sequence[tuple[Any, ...]],
                     fps: float | None) -> list[tuple[Any, ...]]:
    """The search's probes that kept up (:class:`.search.Found`) that a frontier's display pricing
    prices besides the spread of its ``points`` (:func:`spread_points`): those on the meeting tier of the
    two-tier frontier of both (:func:`service.store.frontier_tiers`) that are more accurate than every
    real-time point of ``points``, power ascending; none without a frame-rate target or a real-time
    point. The search leaves them out of its frontier, yet they are often the most accurate real-time
    settings it met: priced, they give an error budget a setting between a slow Max and the search's
    meeting tier. Priced besides the spread, not instead of a point of it: taking the spread's
    least-error end cost the teapot's demo store 4.4 points of its error-budget saving."""
    if not kept_up or fps is None:
        return []
    meeting = [pt for pt in points if meets_frame_rate(float(pt[3]), fps)]
    if not meeting:
        return []
    best = min(float(pt[1]) for pt in meeting)
    pts = [*meeting, *kept_up]
    fast, _ = frontier_tiers([float(pt[1]) for pt in pts], [float(pt[2]) for pt in pts],
                             [meets_frame_rate(float(pt[3]), fps) for pt in pts])
    return [pts[i] for i in fast if i >= len(meeting) and float(pts[i][1]) < best]


#: At most this many of a frontier's slow settings near the deadline are priced (:func:`near_to_price`).
NEAR_POINTS = 4
#: A slow setting near the deadline is priced when its search frame time times the frontier's measured
#: display/search ratio is at most this multiple of the deadline: the ratio is a median over the
#: settings priced, and settings differ around it.
NEAR_SLACK = 1.1


def near_to_price(search_points: Sequence[tuple[Any, ...]], priced: Sequence[tuple[Any, ...]],
                  near: Sequence[tuple[Any, ...]], fps: float | None, k: int = NEAR_POINTS) -> list[Any]:
    """The search's slow settings near the deadline (``near``, :meth:`.search.Search.near_deadline`)
    that a frontier's display pricing prices after its first round: where the most accurate point
    ``priced`` meets the rate at display resolution with an error over :data:`PROBE_ERROR` (or none
    does), those not priced yet that are more accurate, at the search, than every point priced that
    meets the rate there, and whose frame time scaled by the frontier's display/search ratio (the
    median over the settings priced, ``search_points`` holding the search's figures of each) is within
    :data:`NEAR_SLACK` of the deadline; at most ``k``, spread along their error (:func:`_spread`).

    The search prices frame time from its small images scaled by the pixel ratio, which the display
    resolution can beat by a quarter: at the valley's frame 552 at 640x360 the one setting within the
    error budget that keeps up there was judged slow, and the frame missed its budget."""
    if fps is None or not near or k <= 0:
        return []
    at_search = {pt[0]: pt for pt in search_points}
    ratios = [float(pt[3]) / float(at_search[pt[0]][3]) for pt in priced
              if pt[0] in at_search and float(at_search[pt[0]][3]) > 0.0]
    if not ratios:
        return []
    ratio = float(np.median(ratios))
    real_time = [pt for pt in priced if meets_frame_rate(float(pt[3]), fps)]
    if real_time and min(float(pt[1]) for pt in real_time) <= PROBE_ERROR:
        return []
    best = min((float(at_search[pt[0]][1]) for pt in real_time if pt[0] in at_search), default=np.inf)
    done = {pt[0] for pt in priced}
    cands = [pt for pt in near if pt[0] not in done and float(pt[1]) < best
             and meets_frame_rate(ratio * float(pt[3]) / NEAR_SLACK, fps)]
    return [pt[0] for pt in _spread(cands, k)]


def time_left(spent_s: float, done: int, total: int) -> float | None:
    """Seconds left for ``total`` equal jobs when ``done`` of them took ``spent_s`` (None before the
    first is done)."""
    if done <= 0:
        return None
    return spent_s / done * max(total - done, 0)


def _render_share(to_come: int, points: int) -> float:
    """The share of a pricing round's settings it renders (the rest the evaluation cache holds): what the
    rounds after it are expected to render of theirs."""
    return to_come / points if points > 0 else 1.0


#: What pricing one setting at display resolution costs, in the search's wall time per evaluation
#: rendered times the pixel ratio of the display to the evaluation size (:meth:`OctreeBuilder.pricing_time`).
#: Above 1 because the settings priced are frontier points, many of them near Max, and each camera's
#: maximum-quality reference, where most of the search's renders are cheaper settings: 1.6-2.2 on the
#: recorded runs at 320x180 from 64x36 (the teapot's demo job, CPU time; the village's main job, CPU and
#: wall time; bench/RESULTS.md, "The job's time left during the search"). The tile estimator cost about
#: what whole frames cost where it was measured (0.8-1.1x at 640x360), so one factor serves both.
PRICING_COST = 2.0

STRATEGIES: dict[str, type] = {"axis": ViewCubeSampling, "aimed": ViewCubeSampling, "path": PathSampling}


class OctreeBuilder:
    """Builds the octree and its frontiers for one scene and path."""

    def __init__(self, evaluator: Evaluator, space: ParameterSpace, path: PathFrames, config: OctreeConfig,
                 progress: Callable[[Progress], None] | None = None,
                 should_cancel: Callable[[], bool] | None = None,
                 pricer: DisplayPricer | None = None) -> None:
        n = len(path.positions)
        path = PathFrames(
            np.asarray(path.positions, dtype=np.float64).reshape(-1, 3),
            None if path.forwards is None else np.asarray(path.forwards, np.float64),
            None if path.targets is None else np.asarray(path.targets, np.float64),
            None if path.matrices is None else np.asarray(path.matrices, np.float64),
            np.full(n, config.vfov) if path.vfovs is None else np.asarray(path.vfovs, np.float64).reshape(-1),
            (np.full(n, config.width / config.height) if path.aspects is None
             else np.asarray(path.aspects, np.float64).reshape(-1)))
        self.space = space
        self.cfg = config
        root_min, root_size = root_cube(path.positions, config.pad_fraction, config.min_size,
                                        rest_on_path=config.view_sampling != "axis")
        self.lattice = Lattice(root_min, root_size, config.max_depth)
        self.search = Search(evaluator, space, config.nsga, config.exhaustive_limit, progress, should_cancel,
                             descent_steps=config.descent_steps)
        strategy = STRATEGIES[config.view_sampling]
        self.sampling: CameraSampling = strategy(self.lattice, self.search, config, path)
        if (config.display is None) != (pricer is None):
            raise ValueError("display pricing needs both the display resolution and a pricer")
        self.pricer = pricer
        self.display_cameras = 0  # cameras priced at display resolution
        self.display_points = 0  # frontier points priced there
        self.bridged_points = 0  # of them, priced between the first ones' error jumps (:mod:`.bridge`)
        self.probed_points = 0  # of them, the search's probes that kept up (:meth:`_probes_to_price`)
        self.near_points = 0  # of them, the search's slow settings near the deadline (:func:`near_to_price`)
        self._bridge_reserve = 0  # settings the bridging may still price (in the steps planned, not priced)
        # per lattice frontier id priced at several cameras: (cameras, settings, error, power and frame
        # time (K, n) of each setting at each camera), what the store keeps as its per-camera figures
        self.priced: dict[int, PerCamera] = {}
        # per lattice frontier id: (the points list, fps) it was counted for and the count of its points
        # the display pricing keeps (_kept_count)
        self._kept_counts: dict[int, tuple[list[Any], float | None, int]] = {}
        if pricer is not None:  # the search's time left and fraction done include the pricing after it
            self.search.renders_after = self._pricing_renders_ahead

    @property
    def state(self) -> Progress:
        return self.search.state

    def run(self) -> None:
        self.sampling.build()
        self.priced = dict(self.sampling.priced_figures())
        if self.pricer is not None:
            self._price_at_display()
        self.search.finish()

    def pricing_time(self, state: Progress, cameras: int, points: float) -> float | None:
        """Seconds to price ``points`` settings at ``cameras`` display cameras, from the search's pace.

        Assumes a render's time grows with its pixel count: each point and each camera's reference
        costs the search's wall time per evaluation rendered so far (``state``) times the display to
        evaluation pixel ratio times :data:`PRICING_COST`. None before the search rendered anything (a
        search answered from the evaluation cache has no pace to go by)."""
        if self.cfg.display is None or state.evaluations <= 0:
            return None
        return self._pricing_renders(cameras, points) * state.elapsed_s / state.evaluations

    def pricing_steps(self, cameras: int, points: float) -> float:
        """Search steps that pricing ``points`` settings at ``cameras`` display cameras is worth, for the
        run's fraction done (:meth:`Search.report`): a step renders about a population of settings at the
        evaluation size, and pricing costs what :meth:`pricing_time` says in such renders."""
        return self._pricing_renders(cameras, points) / max(1, self.cfg.nsga.population)

    def _pricing_renders(self, cameras: int, points: float) -> float:
        """Search renders (at the evaluation size) that pricing ``points`` settings and each of ``cameras``
        references at display resolution costs: :data:`PRICING_COST` x the pixel ratio each."""
        assert self.cfg.display is not None
        ratio = self.cfg.display[0] * self.cfg.display[1] / (self.cfg.width * self.cfg.height)
        return PRICING_COST * ratio * (points + cameras)

    def _pricing_renders_ahead(self) -> float:
        """The display pricing still to come while the search runs, in search renders
        (:meth:`_pricing_renders` of :meth:`_pricing_to_come`): :attr:`Search.renders_after` turns it into
        time left (as :meth:`pricing_time` does) and steps (as :meth:`pricing_steps` does)."""
        return self._pricing_renders(*self._pricing_to_come())

    def _pricing_to_come(self) -> tuple[int, float]:
        """Cameras and points of the display pricing after the search, as far as the search knows them.

        Where the sampling strategy knows the frontiers it will price and their cameras before the search
        ends (:meth:`CameraSampling.pricing_plan`: path samples, once placed, each at its sample camera
        and its own guards, pass cameras and cameras beyond the guard radius, at most ``guard_frames`` of
        each, fewer where a group's frames coincide, lie within the radius or the path passes through it
        once), exactly
        those cameras, each with the points its frontier keeps to be priced (:func:`spread_points`) or,
        for a frontier not found yet, as many as the frontiers found so far keep on average. Otherwise
        (view cubes, or path samples not placed yet) every view planned so far, at its sample camera and
        (path samples) ``guard_frames`` guards, with that average each. Before the first frontier is found,
        ``display_points`` + 1 a frontier: a full meeting tier and one slow point (Max, when it misses the
        frame rate; recorded slow tiers mostly hold one point, bench/RESULTS.md), or a population when
        every point is priced. Each frontier counts ``bridge_points`` more, the most its bridging may
        price (:mod:`.bridge`): the fraction done may jump at the end, never stall at the bridging."""
        cfg = self.cfg
        kept = [self._kept_count(fid) + cfg.bridge_points for fid in range(len(self.lattice.frontiers))]
        per_frontier = (sum(kept) / len(kept) if kept else
                        cfg.display_points + 1 + cfg.bridge_points if cfg.display_points else
                        cfg.nsga.population + cfg.bridge_points)
        plan = self.sampling.pricing_plan()
        if plan is not None:
            return (sum(n for _, n in plan),
                    sum(n * (kept[fid] if fid >= 0 else per_frontier) for fid, n in plan))
        cameras = max(self.state.views_planned, len(kept)) * (1 + cfg.guard_frames
                                                              if cfg.view_sampling == "path" else 1)
        return cameras, cameras * per_frontier

    def _kept_count(self, fid: int) -> int:
        """How many points of lattice frontier ``fid`` the display pricing keeps (:meth:`_to_price`),
        counted once for each points list the frontier holds: a frontier's points are replaced, never
        changed in place, so a list other than the one counted (the guards' worst figures, the pricing's
        spread and figures) is counted again. The counted list is kept with its count, so its identity
        is not reused while the count stands."""
        points, fps = self.lattice.frontiers[fid].points, self.search.ev.fps
        hit = self._kept_counts.get(fid)
        if hit is None or hit[0] is not points or hit[1] != fps:
            n = len(self._to_price(fid))
            hit = self._kept_counts[fid] = (points, fps, n)
        return hit[2]

    def _to_price(self, fid: int) -> list[tuple[Any, ...]]:
        """The points of lattice frontier ``fid`` its display pricing prices first: the spread of its
        points (:func:`spread_points`)."""
        return spread_points(self.lattice.frontiers[fid].points, self.cfg.display_points, self.search.ev.fps,
                             self.cfg.slow_points)

    def _probes_to_price(self, fid: int, priced: list[tuple[Any, ...]]) -> list[Indices]:
        """The search's probes that kept up (:func:`kept_up_to_price`) that frontier ``fid`` prices
        after its first pricing round: all of them where the most accurate real-time point priced
        (``priced``, display figures) is over :data:`PROBE_ERROR` and the slow tier holds a more
        accurate one, none elsewhere. Near Max they are costly renders, and a pricing round of its own
        then rendered each camera's reference again too (read from the build's reference store since,
        :class:`~service.display_pricing.references.ReferenceStore`): priced at every frontier they took
        the teapot's demo from 9.5 to 11.8 minutes, and where the real-time points priced were over 0.01
        (13 of 66 frontiers) to 10.9, for an error budget of 0.02 its store already kept on every
        frame."""
        fps = self.search.ev.fps
        meeting, slow = split_by_rate(priced, fps)
        best = min((float(pt[1]) for pt in meeting), default=0.0)
        if best <= PROBE_ERROR or not any(float(pt[1]) < best for pt in slow):
            return []
        rec = self.lattice.frontiers[fid]
        return [pt[0] for pt in kept_up_to_price(rec.points, rec.kept_up, fps)]

    def _near_to_price(self, fid: int, priced: list[tuple[Any, ...]], probes: list[Indices]) -> list[Indices]:
        """The search's slow settings near the deadline (:func:`near_to_price`) that frontier ``fid``
        prices after its first pricing round, besides its ``probes``."""
        rec = self.lattice.frontiers[fid]
        xs = near_to_price([*rec.points, *rec.kept_up, *rec.near], priced, rec.near, self.search.ev.fps)
        return [x for x in xs if x not in probes]

    def _price_at_display(self) -> None:
        """Every measured frontier's points priced again at the path's resolution at the frontier's
        cameras (its sample, and for path samples its guards), keeping each point's worst error, power
        and frame time there: the store's figures are the display resolution's, the search's only chose
        the points (:func:`spread_points`: at most ``display_points`` of the meeting tier and
        ``slow_points`` of the slow tier). Then, in a second round, the search's probes that kept up
        where the priced real-time points are far from max quality (:meth:`_probes_to_price`), there too
        the slow settings that the display's frame times put within reach of the deadline
        (:func:`near_to_price`), and where
        the priced meeting tier's errors jump, up to ``bridge_points`` more settings between them, a few
        rounds (:mod:`.bridge`). The store's tiers are drawn again from the display figures
        (``Frontier.from_points``): a point may meet the rate at one resolution and miss it at the
        other."""
        assert self.pricer is not None and self.cfg.display is not None
        width, height = self.cfg.display
        search, lat = self.search, self.lattice
        fps = search.ev.fps
        # per frontier: its cameras at display resolution, the settings priced so far and their figures
        # there, (K, n) each: error, power, frame time
        jobs: dict[int, tuple[list[CameraSpec], list[Indices], list[np.ndarray]]] = {}
        asked: dict[int, list[Indices]] = {}
        for fid, cams in sorted(self.sampling.pricing_cameras().items()):
            keep = self._to_price(fid)
            jobs[fid] = ([dataclasses.replace(c, width=width, height=height) for c in cams], [],
                         [np.zeros((len(cams), 0)) for _ in range(3)])
            asked[fid] = [pt[0] for pt in keep]
        # the points to price are known: the estimate is this phase's own from here, and its steps planned,
        # with the most the bridging may price held in reserve (the rounds draw their steps from it)
        search.renders_after = None
        self._bridge_reserve = sum(len(cams) * self.cfg.bridge_points for cams, _, _ in jobs.values())
        search.steps_planned += self.pricing_steps(0, self._bridge_reserve)
        self.bridged_points = 0
        self.probed_points = 0
        self.near_points = 0
        first_count: dict[int, int] = {}  # per frontier, the points its first round and probes priced
        pace_s: float | None = None  # seconds a pricing render took in the rounds so far
        probing = any(lat.frontiers[fid].kept_up or lat.frontiers[fid].near for fid in jobs)
        rounds = 1 + (bridge.ROUNDS if self.cfg.bridge_points > 0 else int(probing))
        for round_ in range(rounds):
            if round_:
                asked = {}
                for fid, (_, xs, figs) in jobs.items():
                    priced = self._worst(xs, figs)
                    probes = self._probes_to_price(fid, priced) if round_ == 1 else []
                    near = self._near_to_price(fid, priced, probes) if round_ == 1 else []
                    left = self.cfg.bridge_points - (len(xs) - first_count[fid])
                    first_count[fid] += len(probes) + len(near)  # neither counts against the bridges
                    more = probes + near + bridge.bridge_candidates(priced, fps, left, [*xs, *probes, *near])
                    self.probed_points += len(probes)
                    self.near_points += len(near)
                    self.bridged_points += len(more) - len(probes) - len(near)
                    if more:
                        asked[fid] = more
                if not asked:
                    break
            pace_s = self._price_round(jobs, asked, bridging=round_ > 0, pace_s=pace_s,
                                       last=round_ == rounds - 1)
            if not round_:
                first_count = {fid: len(xs) for fid, (_, xs, _) in jobs.items()}
        self.priced = {}
        for fid, (cams, xs, (err, pw, ft)) in jobs.items():
            lat.frontiers[fid].points = self._worst(xs, (err, pw, ft))
            lat.frontiers[fid].kept_up = []  # priced: among the points now where not dominated
            lat.frontiers[fid].near = []
            if len(cams) > 1:  # and each camera's, to predict a frame between them
                self.priced[fid] = (cams, xs, err, pw, ft)
            self.display_points += len(xs)
            self.display_cameras += len(cams)

    @staticmethod
    def _worst(xs: list[Indices], figures: Sequence[np.ndarray]) -> list[tuple[Any, ...]]:
        """The points ``xs`` with their worst figures over the cameras (what the budgets are checked
        against)."""
        err, pw, ft = figures
        return [(x, float(e), float(p), float(t))
                for x, e, p, t in zip(xs, err.max(axis=0), pw.max(axis=0), ft.max(axis=0), strict=True)]

    def _price_round(self, jobs: dict[int, tuple[list[CameraSpec], list[Indices], list[np.ndarray]]],
                     asked: dict[int, list[Indices]], bridging: bool, pace_s: float | None,
                     last: bool = False) -> float | None:
        """Price ``asked`` (settings per frontier) at their frontiers' cameras and append them and their
        figures to ``jobs``, reporting progress per batch. ``pace_s``: seconds a pricing render (in
        :meth:`_pricing_renders`' units) took in the rounds before, the time left's first guess for a
        bridging round; returns this round's. The time left includes the bridging rounds after this one
        (the most they may price) unless it is the ``last``."""
        search = self.search
        requests = [(cam, xs) for fid, xs in asked.items() for cam in jobs[fid][0]]
        # what each camera priced at display resolution costs in search steps (the fraction done, and the
        # time left when the search rendered nothing to take a pace from, pricing_time)
        # (a bridging round's cameras read their reference from the pricer's reference store)
        phase = "price between the priced points" if bridging else "price at display resolution"
        refs = 0 if bridging else 1
        steps = [self.pricing_steps(refs, len(xs)) for _, xs in requests]
        points = sum(len(xs) for _, xs in requests)
        reserved = min(self._bridge_reserve, points) if refs == 0 else 0
        self._bridge_reserve -= reserved
        search.steps_planned += sum(steps) - self.pricing_steps(0, reserved)
        done = search.steps_done
        search.check_cancel()
        # a bridging round goes by the rounds before it: the search's pace, taken over its renders,
        # counts the display pricing's time too, and over a search answered from the cache gave hours
        renders = self._pricing_renders(refs * len(requests), points)
        # the bridging rounds still to come after this one (the most they may price, as in the fraction
        # done): the last batch of a round is not the job's end (the hall's first round at 640x360 read
        # 87 s left for an hour of bridging after it)
        after = 0 if last else self._bridge_reserve
        # the settings of this round the evaluation cache does not hold, where the pricer can tell: a
        # rerun or a resumed job renders only those (its first batches, cached, took no time and made a
        # pace over them promise minutes for an hour's work), and the rounds after it as many in share
        count = getattr(self.pricer, "uncached", None)
        to_come = count(requests) if count is not None else None
        ahead = points + after if to_come is None else to_come + _render_share(to_come, points) * after
        guess_s = (pace_s * self._pricing_renders(0, ahead) if bridging and pace_s is not None
                   else self.pricing_time(search.state, len(requests), ahead))
        search.report(phase, remaining_s=guess_s)
        # cameras per batch: several per worker, so that a batch's last camera (whose cost varies with
        # its points) leaves the other workers idle for a small share of the batch only
        chunk = max(2, 8 * int(getattr(self.pricer.ev.executor, "workers", 1) or 1))  # type: ignore[union-attr]
        results: list[list[Any]] = []
        rendered_before = getattr(self.pricer, "evaluations", None)  # settings the pricer rendered so far
        started = time.perf_counter()

        def report(start: int, rendered: int | None = None, to_render: int = 0) -> None:
            # progress in the batch of cameras requests[start:start + chunk]: ``rendered`` of its
            # ``to_render`` uncached settings while it renders (a batch at display resolution took over ten
            # minutes on the village at 640x360 with nothing shown, nor any cancel seen), or the batch done
            if rendered is not None:  # a cancel stops the batch itself (its cameras take minutes)
                search.check_cancel()
            end = min(start + chunk, len(requests))
            part = 1.0 if rendered is None else rendered / to_render if to_render > 0 else 0.0
            search.steps_done = done + sum(steps[:start]) + part * sum(steps[start:end])
            # pricing is the last phase, and its cameras cost what the scene makes them cost at display
            # resolution, which pricing_time guesses from the search's pace and pixel counts only: from the
            # first render on, the time left is this round's own pace
            left_s = self._round_time_left(time.perf_counter() - started, requests, end, rendered_before,
                                           rendered, to_render, after=after, to_come=to_come)
            if left_s is None and rendered is None and end >= len(requests):
                # the round is done with no pace of its own (the evaluation cache answered it): the rounds
                # after it, by the pace before it or the search's guess
                left_s = (pace_s * self._pricing_renders(0, after) if pace_s is not None
                          else self.pricing_time(search.state, 0, after))
            search.report(phase, remaining_s=guess_s if left_s is None else left_s)

        for start in range(0, len(requests), chunk):
            search.check_cancel()
            results += self.pricer.price(requests[start:start + chunk],  # type: ignore[union-attr]
                                         on_progress=functools.partial(report, start))
            report(start)
        if rendered_before is not None and points > 0:
            # a round answered from the evaluation cache (a rerun from a copied data folder) has no pace:
            # taken over what it asked for, it told the bridging after it that an hour's work was ~0 s
            renders *= (self.pricer.evaluations - rendered_before) / points  # type: ignore[union-attr]
        round_pace_s = (time.perf_counter() - started) / renders if renders > 0 else pace_s
        res = iter(results)
        for fid, xs in asked.items():
            cams, have, figs = jobs[fid]
            evs = [next(res) for _ in cams]
            new = [np.asarray([[getattr(e, name) for e in ev] for ev in evs],
                              dtype=np.float64).reshape(len(cams), len(xs))
                   for name in ("error", "power_w", "frame_time_s")]
            jobs[fid] = (cams, have + list(xs), [np.concatenate((a, b), axis=1) for a, b in zip(figs, new,
                                                                                               strict=True)])
        return round_pace_s

    def _round_time_left(self, spent_s: float, requests: list[tuple[CameraSpec, list[Indices]]], end: int,
                         rendered_before: int | None, rendered: int | None = None,
                         to_render: int = 0, after: int = 0, to_come: int | None = None) -> float | None:
        """Seconds left for a pricing round's ``requests`` after ``spent_s``, in the batch that ends at
        ``requests[end]``: ``rendered`` of its ``to_render`` uncached settings so far, or all of it done
        (None), and for ``after`` settings the rounds after it may price; None while nothing was
        rendered. Settings the evaluation cache answered take no time: the pace is per setting rendered,
        and the requests after the batch, and those ``after`` it, are expected to need rendering in the
        share the round's requests up to ``end`` did (a rerun from a copied data folder whose first
        bridging batch was cached reported ~0 s left for an hour of renders). ``to_come``: the settings of
        the round the cache did not hold when it started (:meth:`DisplayPricer.uncached`), where known: then
        the renders left are exactly those not rendered yet, and the rounds after it are expected to need
        rendering in that share."""
        if rendered is None and end >= len(requests) and after <= 0:  # the last round is done
            return 0.0
        if rendered_before is None:  # (a pricer that does not count its renders)
            if rendered is not None:
                return None
            if after <= 0:
                return time_left(spent_s, end, len(requests))
            done = sum(len(xs) for _, xs in requests[:end])
            return spent_s / done * (sum(len(xs) for _, xs in requests[end:]) + after) if done > 0 else None
        if rendered is None:  # the batch is done, and the pricer has counted its renders
            rendered = to_render = 0
        counted = self.pricer.evaluations - rendered_before  # type: ignore[union-attr]  # (batches done)
        if to_come is not None:
            done = counted + rendered
            points = sum(len(xs) for _, xs in requests)
            if done <= 0:
                return None
            return spent_s / done * (max(to_come - done, 0) + _render_share(to_come, points) * after)
        asked = sum(len(xs) for _, xs in requests[:end])
        if counted + rendered <= 0 or asked <= 0:
            return None
        share = min(1.0, (counted + to_render) / asked)
        later = sum(len(xs) for _, xs in requests[end:]) + after
        return spent_s / (counted + rendered) * (to_render - rendered + share * later)

    def _priced_figures(self, fid: int, frontier: Frontier) -> PricedFigures | None:
        """The per-camera figures of lattice frontier ``fid`` for its store frontier (the points it
        kept, in its order); None when it was priced at one camera."""
        rec = self.priced.get(fid)
        scale = self.sampling.pricing_scales().get(fid)
        if rec is None or scale is None:
            return None
        cams, xs, err, pw, ft = rec
        column = {self.space.pack(x): j for j, x in enumerate(xs)}
        cols = [column[int(p)] for p in frontier.packed]
        return PricedFigures(np.asarray([c.eye for c in cams]), np.asarray([c.forward for c in cams]), scale,
                             frontier.packed, np.clip(err[:, cols], 0.0, 1.0), pw[:, cols], ft[:, cols])

    def to_store(self, *, profile: str, fps: float, aspect: float, meta: dict) -> ParetoStore:
        """The runtime store: nodes in creation order (children consecutive), shared frontiers."""
        return self.lattice.store(self.space, vfov=self.cfg.vfov, aspect=aspect, profile=profile, fps=fps,
                                  meta=meta, cameras=self.sampling.store_cameras,
                                  priced=self._priced_figures if self.priced else None)
