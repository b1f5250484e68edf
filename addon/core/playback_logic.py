"""Per-frame playback logic: store lookup for a camera pose and budget, then the temporal filter (along
the frontier: every shown setting is a point of the frame's frontier that keeps the budget whenever the
target does, :mod:`service.store.temporal`).

Pure (no bpy); the Blender handler in `playback.py` only reads the camera and writes the result.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from service import store as pareto_store
from service.options import check_query

BUDGET_MODES = ("POWER", "ERROR")


def validate_budget(mode: str, value: float) -> float:
    """Check a budget before it reaches the store: power in watts > 0, error in [0, 1], both finite."""
    if mode not in BUDGET_MODES:
        raise ValueError(f"budget mode must be one of {BUDGET_MODES}, got {mode!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{mode.lower()} budget must be finite, got {value!r}")
    if mode == "POWER" and v <= 0.0:
        raise ValueError(f"power budget must be > 0 W, got {v}")
    if mode == "ERROR" and not 0.0 <= v <= 1.0:
        raise ValueError(f"error budget (1 - SSIM) must be in [0, 1], got {v}")
    return v


def missed_rate_text(fps_target: float | None, priority: str) -> str:
    """Why a frame's settings miss the frame-rate target ``fps_target`` (None or 0: unknown) under the
    lookup's ``priority``: worded once for the HUD, the panel and the render engine's frame notes (image
    metadata), so every place says the same thing."""
    target = f"{fps_target:g} fps" if fps_target else "the frame rate"
    if priority == "budget":
        return f"budget first: misses {target} here (nothing within the budget keeps up)"
    return f"no setting keeps up with {target} here"


#: The other per-frame flags, each worded once as (short, long): the HUD's one line of flags takes the
#: short forms; the panels and the render engine's frame notes (image metadata) the long ones, which also
#: say what the frame gets instead. Keys are the flags' field names (``PlaybackFrame``, the engine's
#: ``FrameSettings`` and per-frame CSV columns).
FRAME_FLAGS: dict[str, tuple[str, str]] = {
    "infeasible": ("budget cannot be met",
                   "budget cannot be met here: the setting closest to it is used"),
    "clamped": ("camera outside the optimised area",
                "camera outside the optimised area: the settings of its nearest edge are used"),
    "in_transition": ("blending", "blending towards this view's settings over the filter time"),
}


def frame_flags(*, infeasible: bool = False, slow: bool = False, clamped: bool = False,
                in_transition: bool = False, fps_target: float | None = None, priority: str = "frame_rate",
                short: bool = False) -> list[str]:
    """What is flagged on one frame, most serious first: the words of :data:`FRAME_FLAGS` (``short``:
    the HUD's forms) and, for ``slow`` settings that miss ``fps_target``, :func:`missed_rate_text`.
    The one source of the HUD's, the panels' and the render engine's flags, so none words them apart."""
    form = 0 if short else 1
    texts = [FRAME_FLAGS["infeasible"][form]] if infeasible else []
    if slow:
        texts.append(missed_rate_text(fps_target, priority))
    texts += [FRAME_FLAGS[name][form] for name, on in (("clamped", clamped), ("in_transition", in_transition))
              if on]
    return texts


@dataclass(frozen=True)
class PlaybackFrame:
    """What the handler writes for one frame."""

    active_indices: tuple[int, ...]  # after the temporal filter: what is applied (a frontier point)
    target_indices: tuple[int, ...]  # the store's choice for this pose and budget
    active_settings: dict[str, Any]
    predicted_power_w: float  # of the active settings (a point of this frame's frontier) at this camera
    predicted_error: float  # likewise (ParetoStore.expected)
    clamped: bool
    infeasible: bool
    predicted_fps: float | None = None  # the frame rate the active settings reach (None: store predates it)
    meets_fps: bool | None = None  # they keep up with the frame-rate target (False: no setting does)
    fps_target: float | None = None  # the frame rate asked for (the store's unless the caller gave one)
    priority: str = "frame_rate"  # what gave way when nothing keeps both (service.options.QUERY_PRIORITY)

    @property
    def in_transition(self) -> bool:
        return self.active_indices != self.target_indices

    def settings_text(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.active_settings.items())


class PlaybackDriver:
    """Holds one parsed store and one temporal filter; `step()` is called once per frame change.

    Store lookups (with the frontier points that keep the budget, the settings the filter may show) are
    memoised on their exact inputs (camera matrix, fov, aspect, budget, query options): the lookup is a
    pure function of them, and playback replays the same poses over and over (loops, scrubbing), so a
    replayed frame costs a dictionary hit instead of a frustum/octree query. The filter always runs.
    """

    MEMO_LIMIT = 50_000

    def __init__(self, store: pareto_store.ParetoStore, period_s: float = 2.0) -> None:
        self.store = store
        self.filter = pareto_store.TemporalFilter(period_s)
        self._memo: dict[tuple, Any] = {}
        self.memo_hits = 0

    @property
    def period_s(self) -> float:
        return self.filter.period_s

    def set_period(self, period_s: float) -> None:
        """Change T; restarts filtering from the next frame (the current target then holds)."""
        if period_s != self.filter.period_s:
            self.filter = pareto_store.TemporalFilter(period_s)

    def step(self, matrix_world: Sequence[Sequence[float]], vfov: float, aspect: float, now_s: float,
             budget_mode: str, budget_value: float, **query: Any) -> PlaybackFrame:
        """The settings of one frame under the lookup's ``query`` options
        (``service.options.QUERY_OPTIONS``: ``fps``, the frame-rate target, default the store's;
        ``priority``, what gives way when no setting keeps both the budget and that rate; the margins,
        how far under its budget the store's figures are kept)."""
        budget = validate_budget(budget_mode, budget_value)
        query = check_query(query)
        rows = tuple(tuple(float(v) for v in matrix_world[r]) for r in range(3))
        key = (rows, float(vfov), float(aspect), budget_mode, budget, *query.values())
        memo = self._memo.get(key)
        if memo is None:
            kwargs = {"power_budget": budget} if budget_mode == "POWER" else {"error_budget": budget}
            m = (*rows, (0.0, 0.0, 0.0, 1.0))
            hit = self.store.lookup((rows[0][3], rows[1][3], rows[2][3]), matrix=m, fov=vfov, aspect=aspect,
                                    **query, **kwargs)
            points = {p.indices: p for p in self.store.budget_points(hit)}
            memo = (hit, points, {k: p.error for k, p in points.items()})
            if len(self._memo) >= self.MEMO_LIMIT:
                self._memo.clear()
            self._memo[key] = memo
        else:
            self.memo_hits += 1
        hit, points, allowed = memo
        active = self.filter.update(hit.indices, now_s, allowed)
        shown = points[active]
        settings = hit.settings if active == hit.indices else self.store.settings_of(active)
        # predicted for this camera (the shown point's figures at its frontier's pricing cameras,
        # interpolated here), not the worst over those cameras that the budget was checked against
        error, power = self.store.expected(hit, shown)
        return PlaybackFrame(active, tuple(hit.indices), settings, power, error, hit.clamped,
                             hit.infeasible, shown.fps, shown.meets_fps, hit.fps_target, hit.priority)


class StoreCache:
    """Parse a store once per (datablock, revision): playback runs every frame, the store rarely changes."""

    def __init__(self) -> None:
        self._key: Any = None
        self._driver: PlaybackDriver | None = None

    def driver(self, key: Any, load_text: Callable[[], str], period_s: float) -> PlaybackDriver:
        if key != self._key or self._driver is None:
            self._driver = PlaybackDriver(pareto_store.ParetoStore.from_json(load_text()), period_s)
            self._key = key
        else:
            self._driver.set_period(period_s)
        return self._driver

    def clear(self) -> None:
        self._key, self._driver = None, None


def predicted_path_summary(store: pareto_store.ParetoStore, frames: Sequence[Any], budget_mode: str,
                           budget_value: float, **query: Any) -> dict[str, Any]:
    """Store size and the power (and frame rate) the store predicts along a path under a budget, against
    the least-error point of the same frontiers (the most accurate setting that keeps up with the
    frame-rate target, where frame times are known): what the panel's summary shows. ``query``: the
    lookup's query options (default: the store's frame rate, frame rate first, no margin).

    Frames where nothing meets the budget are counted, with what the nearest setting costs there: under a
    power budget the cheapest setting's power, under an error budget the most accurate setting's error.
    `frames` are camera_path.CameraFrame objects (matrix_world, vfov, aspect).
    """
    validate_budget(budget_mode, budget_value)
    kwargs = {"power_budget": budget_value} if budget_mode == "POWER" else {"error_budget": budget_value}
    query = check_query(query)
    rate = store.check_fps(query["fps"])
    query["fps"] = rate
    chosen = best = 0.0
    slow = 0
    rates: list[float] = []
    nearest: list[float] = []
    for f in frames:
        pos = f.matrix_world[:3, 3]
        hit = store.lookup(pos, matrix=f.matrix_world, fov=f.vfov, aspect=f.aspect, **query, **kwargs)
        top = store.lookup(pos, matrix=f.matrix_world, fov=f.vfov, aspect=f.aspect, fps=rate,
                           error_budget=0.0)
        chosen += hit.expected_power_w  # predicted for this camera (the stored figures are the worst
        best += top.expected_power_w  # over the frontier's pricing cameras)
        slow += int(hit.meets_fps is False)
        if hit.fps is not None:
            rates.append(hit.fps)
        if hit.infeasible:
            nearest.append(hit.power_w if budget_mode == "POWER" else hit.error)
    stats = store.stats()
    n = max(1, len(frames))
    return {
        "views": stats["views"],
        "corners": stats["corners"],
        "depth": stats["depth"],
        "size_bytes": stats["size_bytes"],
        "budget_mode": budget_mode,
        "budget": float(budget_value),
        "mean_power_w": chosen / n,
        "mean_max_quality_power_w": best / n,
        "predicted_saving": (1.0 - chosen / best) if best > 0 else 0.0,
        "infeasible_frames": len(nearest),
        "nearest_min": min(nearest) if nearest else None,
        "nearest_max": max(nearest) if nearest else None,
        "frames": len(frames),
        "fps_target": rate,
        "priority": query["priority"],
        "mean_fps": sum(rates) / len(rates) if rates else None,  # None: the store predates frame times
        "slow_frames": slow,  # frames whose settings miss fps_target (priority "budget": also by choice)
        # which display the figures hold for, and the size the path renders at (None: not known)
        "figures": store.figures,
        "render_resolution": _render_size(frames),
    }


def _render_size(frames: Sequence[Any]) -> tuple[int, int] | None:
    size = getattr(frames[0], "resolution", None) if len(frames) else None
    return None if size is None else (int(size[0]), int(size[1]))


def figures_label(summary: dict[str, Any]) -> str:
    """Which display the summary's figures hold for, against the size the path renders at."""
    figures = summary.get("figures") or pareto_store.FiguresSize("unknown", None)
    return "figures " + figures.label(summary.get("render_resolution"))


def budget_shortfall(summary: dict[str, Any]) -> str | None:
    """What to tell the user when the budget cannot be met on some frames (None when it can)."""
    k, n = summary["infeasible_frames"], summary["frames"]
    if not k:
        return None
    lo, hi = summary["nearest_min"], summary["nearest_max"]
    where = "on every frame of the path" if k == n else f"on {k} of {n} path frames"
    if summary["budget_mode"] == "POWER":
        span = f"{lo:.3f} W" if hi - lo < 5e-4 else f"{lo:.3f}-{hi:.3f} W"
        return (f"the power budget {summary['budget']:.3f} W cannot be met {where}: the cheapest setting "
                f"costs {span} there (raise the budget to at least {hi:.3f} W)")
    span = f"{lo:.4f}" if hi - lo < 5e-5 else f"{lo:.4f}-{hi:.4f}"
    return (f"the error budget {summary['budget']:.4f} cannot be met {where}: the most accurate setting "
            f"has error {span} there (raise the budget to at least {hi:.4f})")


def summary_text(summary: dict[str, Any]) -> str:
    fps = summary.get("mean_fps")
    rate = ("frame rate unknown (store before frame times)" if fps is None else
            f"{fps:.1f} of {summary['fps_target']:g} fps" + (
                f", {summary['slow_frames']} frames slower" if summary.get("slow_frames") else "") + (
                ", budget first" if summary.get("priority") == "budget" else ""))
    store = (f"{summary['views']} views, {summary['corners']} corners, depth {summary['depth']}, "
             f"{summary['size_bytes'] / 1024:.1f} KB")
    shortfall = budget_shortfall(summary)
    where = figures_label(summary)
    if shortfall:
        return f"{store}; {shortfall}; {rate}; {where}"
    return (f"{store}; predicted {summary['mean_power_w']:.3f} W vs "
            f"{summary['mean_max_quality_power_w']:.3f} W at the most accurate setting "
            f"({100 * summary['predicted_saving']:.1f} % saved), {rate}; {where}")
