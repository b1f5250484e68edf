"""Verify a store against renders: does what it promises hold at the resolution the path is shown at?

A sample of path frames, spread evenly over the path, is looked up in the store under a budget (each frame
on its own, no temporal filter: the store's own promise for that camera). The chosen settings are then
rendered at the path's resolution (or a stated one) together with the store's maximum-quality reference,
and the error and power measured exactly as the optimiser measures them (``service.evaluation.evaluate``:
1 - SSIM after the display transform, the energy model on the render's own counters) are set against the
store's predictions: per frame, the share of frames within the budget, how far the predictions are off,
and the worst frames.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from service.camera_path import CameraPath
from service.evaluation import CameraSpec, evaluate
from service.options import check_query
from service.params import stored_space
from service.stats import share_interval, share_text
from service.store import ParetoStore

#: A prediction holds when the measured power is within this share of it (the issue's 10 % target).
POWER_TOLERANCE = 0.10


@dataclass(frozen=True)
class FrameCheck:
    """One verified frame: the store's choice and prediction, and what a render measured."""

    frame: int
    time: float
    settings: dict[str, Any]
    predicted_error: float
    predicted_power_w: float
    measured_error: float
    measured_power_w: float
    measured_frame_time_s: float
    within_budget: bool
    infeasible: bool  # the store said nothing meets the budget here (it returned its nearest setting)
    clamped: bool  # the camera was outside the store's region
    meets_fps: bool | None = None  # the store says the settings keep up with the frame rate (None: unknown)

    @property
    def power_ratio(self) -> float:
        """Measured / predicted power."""
        return self.measured_power_w / self.predicted_power_w if self.predicted_power_w > 0 else math.inf


@dataclass(frozen=True)
class VerifyReport:
    """Predicted against measured figures of a store on a sample of its path's frames."""

    budget_mode: str  # "error" or "power"
    budget_value: float
    resolution: tuple[int, int]
    profile: str
    fps: float
    frames: list[FrameCheck]
    store_figures_resolution: tuple[int, int] | None  # where the store says its figures were measured
    priority: str = "frame_rate"  # the lookup's (service.options.QUERY_PRIORITY)
    #: how they were measured (service.store.FiguresSize.kind): "display" figures hold for that display,
    #: "preview" ones are the search's small renders (power scaled by the pixel count)
    store_figures_kind: str = "unknown"
    error_margin: float = 0.0  # the lookup's (service.options.QUERY_ERROR_MARGIN)
    power_margin: float = 0.0  # the lookup's (service.options.QUERY_POWER_MARGIN)

    def summary(self) -> dict[str, Any]:
        """Share within budget, prediction errors and the worst frames (by how far over budget)."""
        fr = self.frames
        de = np.asarray([f.measured_error - f.predicted_error for f in fr])
        ratio = np.asarray([f.power_ratio for f in fr])
        return {
            "frames": len(fr),
            "within_budget": int(sum(f.within_budget for f in fr)),
            "share_within_budget": float(np.mean([f.within_budget for f in fr])) if fr else math.nan,
            # how sure that share is, from this many frames (Wilson, 95 %)
            "share_within_budget_interval": (list(share_interval(sum(f.within_budget for f in fr), len(fr)))
                                             if fr else None),
            "mean_abs_error_difference": float(np.mean(np.abs(de))) if fr else math.nan,
            "max_abs_error_difference": float(np.max(np.abs(de))) if fr else math.nan,
            "mean_error_measured": float(np.mean([f.measured_error for f in fr])) if fr else math.nan,
            "median_power_ratio": float(np.median(ratio)) if fr else math.nan,
            "share_power_within_10pct": float(np.mean(np.abs(ratio - 1.0) <= POWER_TOLERANCE)) if fr
            else math.nan,
            "mean_power_measured_w": float(np.mean([f.measured_power_w for f in fr])) if fr else math.nan,
            "worst_frames": [f.frame for f in self.worst(3)],
        }

    def worst(self, k: int) -> list[FrameCheck]:
        """The ``k`` frames furthest over (or least under) the budget, relative to it."""
        def excess(f: FrameCheck) -> float:
            value = f.measured_error if self.budget_mode == "error" else f.measured_power_w
            return value / self.budget_value - 1.0
        return sorted(self.frames, key=excess, reverse=True)[:k]

    def to_dict(self) -> dict[str, Any]:
        return {"budget_mode": self.budget_mode, "budget_value": self.budget_value,
                "resolution": list(self.resolution), "profile": self.profile, "fps": self.fps,
                "priority": self.priority, "error_margin": self.error_margin,
                "power_margin": self.power_margin,
                "store_figures_resolution": (list(self.store_figures_resolution)
                                             if self.store_figures_resolution else None),
                "store_figures_kind": self.store_figures_kind,
                "summary": self.summary(), "frames": [asdict(f) for f in self.frames]}

    def table(self) -> str:
        """A Markdown table of the frames, then the summary (:func:`markdown`)."""
        return markdown(self.to_dict())


def markdown(doc: dict[str, Any]) -> str:
    """A verify report (``VerifyReport.to_dict()``, the REST answer) as a Markdown table of the frames,
    then the summary: what the CLI prints and the demo and the add-on write to verify.md."""
    w, h = doc["resolution"]
    figures = doc.get("store_figures_resolution")
    size = "x".join(str(v) for v in figures) if figures else "an unstated size"
    preview = doc.get("store_figures_kind") == "preview" and figures
    whose = f"the store's preview figures, from {size} renders" if preview else f"store figures for {size}"
    lines = [f"verified at {w}x{h} ({whose}), {doc['budget_mode']} "
             f"budget {doc['budget_value']:g}, profile {doc['profile']} at {doc['fps']:g} fps"
             + (", budget first (the frame rate gives way where nothing within the budget keeps up)"
                if doc.get("priority") == "budget" else "")
             + (f", looked up with a {doc['error_margin']:g} error margin"
                if doc.get("error_margin") and doc["budget_mode"] == "error" else "")
             + (f", looked up with a {100 * doc['power_margin']:g} % power margin"
                if doc.get("power_margin") and doc["budget_mode"] == "power" else ""), "",
             "| frame | time s | error predicted | error measured | power predicted W | power measured W "
             "| measured / predicted | within budget |",
             "|---|---|---|---|---|---|---|---|"]
    for f in doc["frames"]:
        ratio = f["measured_power_w"] / f["predicted_power_w"] if f["predicted_power_w"] > 0 else math.inf
        note = (" (infeasible)" if f["infeasible"] else "") + (
            f" (misses {doc['fps']:g} fps)" if f.get("meets_fps") is False else "")
        lines.append(f"| {f['frame']} | {f['time']:.2f} | {f['predicted_error']:.4f} | "
                     f"{f['measured_error']:.4f} | {f['predicted_power_w']:.3f} | "
                     f"{f['measured_power_w']:.3f} | {ratio:.2f} | "
                     f"{'yes' if f['within_budget'] else 'NO'}{note} |")
    s = doc["summary"]
    within = (share_text(s["within_budget"], s["frames"]) if s["frames"] else
              f"{s['within_budget']}/{s['frames']}")
    lines += ["", f"within budget: {within}",
              f"mean |measured - predicted| error: {s['mean_abs_error_difference']:.4f} "
              f"(max {s['max_abs_error_difference']:.4f})",
              f"measured / predicted power: median {s['median_power_ratio']:.3f}, "
              f"{100 * s['share_power_within_10pct']:.0f} % of frames within 10 %",
              f"worst frames: {', '.join(str(i) for i in s['worst_frames'])}"]
    if figures and not preview and tuple(figures) != (w, h):
        # a stated display size checked at another (the path's own, say): the errors check the picks
        # there, but power and frame time grow with the pixels and are not what the store predicts
        lines.append(f"note: the store's figures are for a {size} display, not {w}x{h}: the errors check its "
                     f"picks at this size, and its power and frame-rate figures are for {size}, so the "
                     f"power ratio above says how far this size's power is from them, not how well they "
                     f"predict")
    return "\n".join(lines)


def sample_frames(n: int, count: int) -> list[int]:
    """``count`` frame numbers spread evenly over a path of ``n`` frames (centres of equal parts)."""
    if n < 1:
        raise ValueError("the path has no frames")
    if count < 1:
        raise ValueError(f"frames to verify must be >= 1, got {count}")
    count = min(count, n)
    return sorted({min(n - 1, int((k + 0.5) * n / count)) for k in range(count)})


def verify_store(scene: Any, store: ParetoStore, path: CameraPath, *, error_budget: float | None = None,
                 power_budget: float | None = None, frames: int = 8,
                 resolution: tuple[int, int] | None = None, threads: int | None = None,
                 progress: Callable[[int, int], None] | None = None, **query: Any) -> VerifyReport:
    """Render a sample of ``path``'s frames at ``resolution`` (default: each frame's own) with the
    settings ``store`` picks under the budget and the lookup's ``query`` options
    (``service.options.QUERY_OPTIONS``: the frame-rate target ``fps``, default the store's, the
    ``priority``, the budget's margin), and measure them at that frame rate against the budget itself;
    ``scene`` is the store's scene."""
    query = check_query(query)
    rate = store.check_fps(query["fps"])  # refused before anything is rendered
    if (error_budget is None) == (power_budget is None):
        raise ValueError("give exactly one of error_budget or power_budget")
    mode, value = ("error", error_budget) if error_budget is not None else ("power", power_budget)
    value = float(value)  # type: ignore[arg-type]
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"the budget must be a positive finite number, got {value!r}")
    if resolution is not None:
        rw, rh = (int(v) for v in resolution)
        if rw < 8 or rh < 8:
            raise ValueError(f"resolution must be at least 8x8, got {resolution!r}")
    metric = str(store.meta.get("metric", "ssim"))
    space = stored_space(store.parameters)  # its job's, so its cache keys are the job's
    # the store's own maximum quality is the reference its errors were measured against (parameters
    # it does not carry at the renderable space's best, as in its lookups' settings)
    best = space.indices_of(store.settings_of([p.max_quality for p in store.parameters]))
    numbers = sample_frames(len(path), frames)
    checks: list[FrameCheck] = []
    size = None
    margins = (0.0, 0.0)  # the lookups' own: a margin applies only to its kind of budget
    for done, number in enumerate(numbers):
        f = path.frames[number]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        r = store.lookup(f.position, matrix=m, fov=f.vfov, aspect=f.aspect, error_budget=error_budget,
                         power_budget=power_budget, **query)
        margins = (r.error_margin, r.power_margin)
        size = (rw, rh) if resolution is not None else tuple(f.resolution)
        cam = CameraSpec.from_matrix(m, f.vfov, *size)
        ev = evaluate(scene, cam, space.indices_of(r.settings), space, profile=store.profile, fps=rate,
                      metric=metric, threads=threads, reference_indices=best)
        within = ev.error <= value if mode == "error" else ev.power_w <= value
        checks.append(FrameCheck(number, float(f.time), dict(r.settings), float(r.expected_error),
                                 float(r.expected_power_w),
                                 float(ev.error), float(ev.power_w), float(ev.frame_time_s), bool(within),
                                 bool(r.infeasible), bool(r.clamped), r.meets_fps))
        if progress is not None:
            progress(done + 1, len(numbers))
    figures = store.figures
    return VerifyReport(mode, value, size or (0, 0), store.profile, rate, checks, figures.resolution,
                        query["priority"], figures.kind, *margins)
