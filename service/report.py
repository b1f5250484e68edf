"""Path reports: the power-budget paper's Table 3 (average power and error per mode) and its plots.

Input is a list of per-frame records for every mode (presets and budget-driven modes), produced by
:mod:`service.path_eval`; output is a report folder a person reads: ``report.md``, ``frames.csv``,
``power.png`` / ``error.png`` (Figures 9-11 layout) and ``summary.json``.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class FrameRecord:
    """Predicted-versus-measured figures of one frame rendered in one mode."""

    mode: str
    frame: int
    time_s: float
    packed: int
    power_w: float
    error: float
    predicted_power_w: float | None = None
    predicted_error: float | None = None
    clamped: bool = False
    infeasible: bool = False
    settings: str = ""

    def __post_init__(self) -> None:
        for name in ("time_s", "power_w", "error"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"frame {self.frame} ({self.mode}): {name} is not finite")


@dataclass(frozen=True)
class ModeSummary:
    """One row of Table 3."""

    mode: str
    frames: int
    mean_power_w: float
    mean_error: float
    max_error: float
    power_saving: float  # fraction of the maximum-quality mode's mean power saved
    budget: str = ""
    budget_kept: float | None = None  # fraction of frames that met the mode's budget


@dataclass
class PathReport:
    """Everything a report folder shows; ``meta`` carries scene, profile, store size and timings."""

    scene: str
    records: list[FrameRecord]
    budgets: dict[str, tuple[str, float]] = field(default_factory=dict)  # mode -> ("power"|"error", v)
    meta: dict[str, Any] = field(default_factory=dict)
    reference_mode: str = "maximum"

    def modes(self) -> list[str]:
        seen: list[str] = []
        for r in self.records:
            if r.mode not in seen:
                seen.append(r.mode)
        return seen

    def summarize(self) -> list[ModeSummary]:
        by_mode: dict[str, list[FrameRecord]] = {}
        for r in self.records:
            by_mode.setdefault(r.mode, []).append(r)
        if self.reference_mode not in by_mode:
            raise ValueError(f"report needs the {self.reference_mode!r} mode as its power reference")
        ref_power = _mean([r.power_w for r in by_mode[self.reference_mode]])
        rows = []
        for mode in self.modes():
            recs = by_mode[mode]
            mean_p = _mean([r.power_w for r in recs])
            budget_text, kept = "", None
            if mode in self.budgets:
                kind, value = self.budgets[mode]
                budget_text = f"{kind} <= {value:g}"
                if kind == "power":
                    kept = sum(r.power_w <= value * (1 + 1e-9) for r in recs) / len(recs)
                else:
                    kept = sum(r.error <= value * (1 + 1e-9) for r in recs) / len(recs)
            rows.append(ModeSummary(
                mode=mode, frames=len(recs), mean_power_w=mean_p,
                mean_error=_mean([r.error for r in recs]), max_error=max(r.error for r in recs),
                power_saving=(1.0 - mean_p / ref_power) if ref_power > 0 else 0.0,
                budget=budget_text, budget_kept=kept,
            ))
        return rows


def _mean(values: Sequence[float]) -> float:
    if not values:
        raise ValueError("no frames to average")
    return float(sum(values) / len(values))


def table3_markdown(rows: Sequence[ModeSummary]) -> str:
    """Table 3 layout: one row per mode with average power and error."""
    lines = [
        "| mode | budget | frames | avg power (W) | saved vs max | avg error (1-SSIM) | max error "
        "| budget kept |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        kept = "" if r.budget_kept is None else f"{100 * r.budget_kept:.1f} %"
        lines.append(
            f"| {r.mode} | {r.budget} | {r.frames} | {r.mean_power_w:.4f} | {100 * r.power_saving:.1f} % | "
            f"{r.mean_error:.4f} | {r.max_error:.4f} | {kept} |"
        )
    return "\n".join(lines)


def write_report(report: PathReport, out_dir: Path) -> dict[str, Path]:
    """Write report.md, frames.csv, summary.json and the power/error plots; return their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = report.summarize()
    paths = {
        "csv": out_dir / "frames.csv",
        "summary": out_dir / "summary.json",
        "report": out_dir / "report.md",
        "power_plot": out_dir / "power.png",
        "error_plot": out_dir / "error.png",
    }
    with paths["csv"].open("w", newline="") as fh:
        names = list(FrameRecord.__dataclass_fields__)
        writer = csv.DictWriter(fh, fieldnames=names)
        writer.writeheader()
        for r in report.records:
            writer.writerow(asdict(r))
    paths["summary"].write_text(json.dumps(
        {"scene": report.scene, "meta": report.meta, "modes": [asdict(r) for r in rows]}, indent=2))
    _plot(report, "power_w", "power (W)", paths["power_plot"])
    _plot(report, "error", "error (1 - SSIM)", paths["error_plot"])

    meta_lines = [f"- {k}: {v}" for k, v in report.meta.items()]
    text = [
        f"# Power-budget report: {report.scene}",
        "",
        "Average power and error along the camera path per mode (layout of the power-budget paper's "
        "Table 3). Power is the simulated GPU's at the profile's frame rate; error is 1 - SSIM against "
        "the maximum-quality render of the same frame.",
        "",
        table3_markdown(rows),
        "",
        "![power over time](power.png)",
        "",
        "![error over time](error.png)",
        "",
        "## Run",
        *meta_lines,
        "",
        "Per-frame figures: `frames.csv`.",
        "",
    ]
    paths["report"].write_text("\n".join(text))
    return paths


def _plot(report: PathReport, attr: str, label: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.2), dpi=110)
    for mode in report.modes():
        recs = [r for r in report.records if r.mode == mode]
        ax.plot([r.time_s for r in recs], [getattr(r, attr) for r in recs], label=mode, linewidth=1.2)
        if mode in report.budgets and report.budgets[mode][0] == ("power" if attr == "power_w" else "error"):
            ax.axhline(report.budgets[mode][1], linestyle=":", linewidth=1, color="grey")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(label)
    ax.set_title(f"{report.scene}: {label} along the path")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
