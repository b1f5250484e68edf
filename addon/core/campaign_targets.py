"""What a campaign's report measures itself against: issue 7's targets, the paper's Table 2 and the
background-view diagnostic. Pure (stdlib + numpy + the service's store and path modules)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from service import camera_path
from service import store as pareto_store
from service.stats import share_interval, share_text

from . import report

CameraPath = camera_path.CameraPath
ParetoStore = pareto_store.ParetoStore

#: The paper's Table 2 (published figures, shown next to ours for comparison; not our results).
PAPER_TABLE2 = (
    # demo, triangles, thresholds (W, e), preprocess hours, levels, corners, views, data KB, duration s
    ("Valley (paper)", "55.9 k", "(0.5 W, 0.002)", "29.9 h", 4, 279, 759, "18.1 KB", "50 s"),
    ("Hall (paper)", "31.7 k", "(0.15 W, 0.002)", "35.3 h", 4, 108, 316, "9.3 KB", "50 s"),
    ("Elven Ruins (paper)", "191.2 k", "(0.5 W, 0.005)", "67.1 h", 5, 393, 956, "36.6 KB", "60 s"),
    ("Sun Temple (paper)", "667.9 k", "(0.5 W, 0.005)", "35.4 h", 3, 125, 511, "18 KB", "60 s"),
)

#: Issue 7's targets (checked and reported, never used to choose anything).
TARGET_SAVING = 0.30
TARGET_ERROR = 0.02
TARGET_ERROR_RATIO = 5.0
TARGET_KEPT = 0.95
STORE_LIMIT_BYTES = 40 * 1024


def check_targets(summaries: Sequence[report.ModeSummary]) -> dict[str, Any]:
    """Issue 7's targets on this run's measured numbers."""
    by = {s.mode: s for s in summaries}
    ours_e, ours_p, mn = by.get("ours_error"), by.get("ours_power"), by.get("min")
    out: dict[str, Any] = {}
    if ours_e is not None and ours_e.saving_vs_max is not None:
        out["error_budget_saving"] = ours_e.saving_vs_max
        out["error_budget_mean_error"] = ours_e.mean_error
        out["error_budget_saving_met"] = bool(ours_e.saving_vs_max >= TARGET_SAVING
                                              and ours_e.mean_error <= TARGET_ERROR)
    if ours_p is not None and mn is not None:
        ratio = mn.mean_error / ours_p.mean_error if ours_p.mean_error > 0 else math.inf
        out["power_budget_error_ratio_vs_min"] = ratio
        out["power_budget_error_ratio_met"] = bool(ratio >= TARGET_ERROR_RATIO)
    for name, s in (("error", ours_e), ("power", ours_p)):
        if s is not None and s.budget_kept_fraction is not None:
            out[f"{name}_budget_kept"] = s.budget_kept_fraction
            out[f"{name}_budget_kept_met"] = bool(s.budget_kept_fraction >= TARGET_KEPT)
            if s.budget_kept_counts is not None:  # and how sure the share is, from this many frames
                out[f"{name}_budget_kept_frames"] = list(s.budget_kept_counts)
                out[f"{name}_budget_kept_interval"] = list(share_interval(*s.budget_kept_counts))
    met = [v for k, v in out.items() if k.endswith("_met")]
    out["all_met"] = bool(met) and all(met)
    return out


def target_lines(targets: dict[str, Any], store_bytes: int) -> list[str]:
    """The targets as four report bullets (also printed by the demo)."""
    nan = float("nan")
    kept = targets.get("power_budget_kept_met") and targets.get("error_budget_kept_met")
    return [
        f"- error budget: {100 * targets.get('error_budget_saving', nan):.1f} % power saved vs Max at mean "
        f"error {targets.get('error_budget_mean_error', nan):.4f} (target >= 30 % at <= 0.02): "
        + ("met" if targets.get("error_budget_saving_met") else "MISSED"),
        f"- power budget: Min's error / ours = {targets.get('power_budget_error_ratio_vs_min', 0):.1f}x "
        f"(target >= 5x): {'met' if targets.get('power_budget_error_ratio_met') else 'MISSED'}",
        f"- budget kept: power {_kept(targets, 'power')}, error {_kept(targets, 'error')} of frames "
        "(target >= 95 %): " + ("met" if kept else "MISSED"),
        f"- store {store_bytes / 1024:.1f} KB (target <= 40 KB): "
        + ("met" if store_bytes <= STORE_LIMIT_BYTES else "MISSED"),
    ]


def _kept(targets: dict[str, Any], name: str) -> str:
    """``11/12 (92 %; 95 % interval 65-99 %)``: a budget-kept share, the frames behind it and how sure it
    is (the share alone where the counts are not known)."""
    frames = targets.get(f"{name}_budget_kept_frames")
    if frames:
        return share_text(*frames)
    return f"{100 * targets.get(f'{name}_budget_kept', 0):.1f} %"


def background_views(store: ParetoStore, path: CameraPath, frames: Sequence[int], tol: float = 1e-3
                     ) -> tuple[int, int, float]:
    """Store views whose whole frontier has error < ``tol`` (every setting looks the same there: the view
    sees background only), and the share of evaluated frames whose lookup lands on such a view."""
    n_corners = len(store.corner_positions())
    flat = {(c, v) for c in range(n_corners) for v in range(6)
            if float(np.max(store.frontier(c, v).error)) < tol}
    hits = []
    for i in frames:
        f = path.frames[i]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        hits.append(store.locate(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect) in flat)
    return len(flat), 6 * n_corners, float(np.mean(hits)) if hits else 0.0


@dataclass(frozen=True)
class Preprocessing:
    """How the store was made, for the row next to the paper's Table 2."""

    name: str
    triangles: int | None = None
    wall_s: float | None = None  # the optimisation's wall time (None: the store's own elapsed_s)
    cpu_s: float | None = None


def table2_markdown(rows: Sequence[Sequence[Any]]) -> str:
    head = ("Demo", "Tris.", "Thld. (power, error) or path sampling", "Preprocess", "Levels", "Corners",
            "Views", "Data size", "Duration")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def table2_row(pre: Preprocessing, store: ParetoStore, path: CameraPath) -> tuple[Any, ...]:
    st, meta = store.stats(), store.meta
    sampling = (f"path {meta.get('path_resolution', 0):g} x view dist., {meta.get('guard_frames', 0)} guards"
                if meta.get("view_sampling") == "path" else
                f"({meta['thresholds']['power_w']:g} W, {meta['thresholds']['error']:g})")
    wall = pre.wall_s if pre.wall_s is not None else float(meta.get("elapsed_s") or 0.0)
    cpu = "" if pre.cpu_s is None else f" ({pre.cpu_s / 60:.1f} CPU min)"
    triangles = "?" if pre.triangles is None else f"{pre.triangles:,}"
    return (f"{pre.name} (ours)", triangles, sampling, f"{wall / 60:.1f} min{cpu}",
            st["depth"], st["corners"], st["unique_frontiers"], f"{st['size_bytes'] / 1024:.1f} KB",
            f"{path_duration(path):.0f} s")


def path_duration(path: CameraPath) -> float:
    return path.frames[-1].time - path.frames[0].time + 1.0 / path.fps
