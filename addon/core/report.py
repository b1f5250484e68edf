"""Path-evaluation report data: per-frame rows, the power-budget paper's Table 3, CSV and plots.

Pure (stdlib + numpy). Plotting needs matplotlib, which a stock Blender lacks: `plot_over_time` raises
ImportError there, and the module can be run as a script by another Python to draw the plots from the
CSV (`python report.py plot per_frame.csv OUT_DIR`).
"""

from __future__ import annotations

import csv
import math
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

#: Fixed presets of the paper's comparison, as a quality level in [0, 1] (1 = every parameter at max).
PRESET_LEVELS: dict[str, float] = {"max": 1.0, "max_mid": 0.75, "mid_min": 0.25, "min": 0.0}
MODE_LABELS: dict[str, str] = {
    "ours": "Ours",
    "ours_power": "Ours (power budget)",
    "ours_error": "Ours (error budget)",
    "max": "Max",
    "max_mid": "Max-Mid",
    "mid_min": "Mid-Min",
    "min": "Min",
}
CSV_FIELDS = ("frame", "time_s", "mode", "power_w", "error", "settings", "budget_kept", "predicted_power_w",
              "predicted_error", "fps", "deadline_met", "predicted_fps")


@dataclass(frozen=True)
class FrameRow:
    """Figures of one frame rendered in one mode. ``power_w`` is drawn at ``fps``, the frame rate the
    modelled GPU reaches (the path's when the frame meets its deadline, else its own lower rate)."""

    frame: int
    time_s: float
    mode: str
    power_w: float
    error: float
    settings: str = ""  # human-readable or packed settings, for the CSV
    budget_kept: bool | None = None  # only meaningful for budget-driven modes
    predicted_power_w: float | None = None  # the store's, of the shown settings (budget-driven modes)
    predicted_error: float | None = None
    fps: float | None = None  # the frame rate reached (None: not measured, e.g. an older CSV)
    deadline_met: bool | None = None  # the frame keeps up with the path's frame rate
    predicted_fps: float | None = None  # the store's (budget-driven modes, stores with frame times)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.power_w) and math.isfinite(self.error)):
            raise ValueError(f"non-finite power/error at frame {self.frame} ({self.mode})")
        for rate in (self.fps, self.predicted_fps):
            if rate is not None and not (math.isfinite(rate) and rate > 0):
                raise ValueError(f"frame rates must be finite and positive at frame {self.frame} "
                                 f"({self.mode})")


@dataclass(frozen=True)
class Section:
    """A titled part of report.md after Table 3 and the notes (lines are Markdown)."""

    heading: str
    lines: Sequence[str]


@dataclass(frozen=True)
class ModeSummary:
    mode: str
    frames: int
    mean_power_w: float
    mean_error: float
    saving_vs_max: float | None  # fraction of the max preset's mean power saved
    budget_kept_counts: tuple[int, int] | None  # (frames that kept the budget, frames checked); None: none
    mean_fps: float | None = None  # mean frame rate reached (None: not measured)
    min_fps: float | None = None
    real_time_fraction: float | None = None  # share of frames that keep up with the path's frame rate

    @property
    def budget_kept_fraction(self) -> float | None:
        """Share of the frames checked that kept the budget (None: a mode without a budget)."""
        if self.budget_kept_counts is None:
            return None
        kept, checked = self.budget_kept_counts
        return kept / checked

    @property
    def real_time(self) -> bool | None:
        """Every frame keeps up with the path's frame rate (None: not measured)."""
        return None if self.real_time_fraction is None else self.real_time_fraction >= 1.0


def preset_indices(value_counts: Sequence[int], max_quality: Sequence[int], level: float) -> list[int]:
    """Parameter indices of a fixed preset: level 1 = every parameter at its maximum-quality value,
    0 = at the opposite end of its value list, in between rounded per parameter (the paper's presets)."""
    if len(value_counts) != len(max_quality):
        raise ValueError("value_counts and max_quality differ in length")
    if not 0.0 <= level <= 1.0:
        raise ValueError(f"preset level must be in [0, 1], got {level}")
    out = []
    for n, mq in zip(value_counts, max_quality, strict=True):
        if n < 1 or not 0 <= mq < n:
            raise ValueError(f"bad parameter: {n} values, max-quality index {mq}")
        lo = n - 1 if mq == 0 else 0
        out.append(math.floor(lo + level * (mq - lo) + 0.5))
    return out


def summarise(rows: Iterable[FrameRow]) -> list[ModeSummary]:
    """Average power and error per mode (Table 3), with the saving against the `max` preset."""
    by_mode: dict[str, list[FrameRow]] = {}
    for r in rows:
        by_mode.setdefault(r.mode, []).append(r)
    if not by_mode:
        raise ValueError("no frames to summarise")
    means = {m: (sum(r.power_w for r in rs) / len(rs), sum(r.error for r in rs) / len(rs))
             for m, rs in by_mode.items()}
    max_power = means["max"][0] if "max" in means else None
    out = []
    for mode, rs in by_mode.items():
        p, e = means[mode]
        saving = (1.0 - p / max_power) if max_power else None
        kept = [r.budget_kept for r in rs if r.budget_kept is not None]
        fps = [r.fps for r in rs if r.fps is not None]
        met = [r.deadline_met for r in rs if r.deadline_met is not None]
        out.append(ModeSummary(mode, len(rs), p, e, saving, (sum(kept), len(kept)) if kept else None,
                               sum(fps) / len(fps) if fps else None, min(fps) if fps else None,
                               sum(met) / len(met) if met else None))
    order = list(MODE_LABELS)
    out.sort(key=lambda s: order.index(s.mode) if s.mode in order else len(order))
    return out


def table3_markdown(summaries: Sequence[ModeSummary], title: str = "") -> str:
    """Modes as columns, average power and error as rows: the layout of the paper's Table 3."""
    labels = [MODE_LABELS.get(s.mode, s.mode) for s in summaries]
    lines = []
    if title:
        lines += [f"### {title}", ""]
    lines.append("| | " + " | ".join(labels) + " |")
    lines.append("|---|" + "---|" * len(labels))
    lines.append("| Avg. Power (W) | " + " | ".join(f"{s.mean_power_w:.3f}" for s in summaries) + " |")
    if any(s.mean_fps is not None for s in summaries):
        lines.append("| Avg. fps (reached) | " + " | ".join(
            "" if s.mean_fps is None else f"{s.mean_fps:.3g}" for s in summaries) + " |")
        lines.append("| Frames at target fps | " + " | ".join(
            "" if s.real_time_fraction is None else f"{100.0 * s.real_time_fraction:.0f} %"
            for s in summaries) + " |")
    lines.append("| Avg. Error (e) | " + " | ".join(f"{s.mean_error:.4f}" for s in summaries) + " |")
    lines.append("| Power saved vs Max | " + " | ".join(
        "" if s.saving_vs_max is None else f"{100.0 * s.saving_vs_max:.1f} %" for s in summaries) + " |")
    if any(s.budget_kept_fraction is not None for s in summaries):
        lines.append("| Budget kept | " + " | ".join(
            "" if s.budget_kept_fraction is None else f"{100.0 * s.budget_kept_fraction:.1f} %"
            for s in summaries) + " |")
    lines.append("| Frames | " + " | ".join(str(s.frames) for s in summaries) + " |")
    return "\n".join(lines) + "\n"


def write_csv(path: str | Path, rows: Iterable[FrameRow]) -> Path:
    path = Path(path)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_FIELDS)
        for r in rows:
            kept = "" if r.budget_kept is None else int(r.budget_kept)
            met = "" if r.deadline_met is None else int(r.deadline_met)
            w.writerow([r.frame, f"{r.time_s:.6f}", r.mode, f"{r.power_w:.6g}", f"{r.error:.6g}",
                        r.settings, kept, _opt(r.predicted_power_w), _opt(r.predicted_error), _opt(r.fps),
                        met, _opt(r.predicted_fps)])
    return path


def _opt(v: float | None) -> str:
    return "" if v is None else f"{v:.6g}"


def real_time_notes(summaries: Sequence[ModeSummary], fps: float, where: str) -> list[str]:
    """Which fixed presets keep up with ``fps`` on every evaluated frame (``where``: the profile and
    resolution, for the sentence), and what power saved against Max means when Max does not."""
    presets = [s for s in summaries if s.mode in PRESET_LEVELS and s.real_time_fraction is not None]
    if not presets:
        return []
    label = {s.mode: MODE_LABELS.get(s.mode, s.mode) for s in presets}
    fast = [label[s.mode] for s in presets if s.real_time]
    slow = [f"{label[s.mode]} ({s.mean_fps:.3g} fps on average, {100 * s.real_time_fraction:.0f} % of frames "
            "at the target)" for s in presets if not s.real_time]
    notes = [f"Real time ({fps:g} fps) {where}: " + (", ".join(fast) or "no preset") + "; not real time: "
             + ("; ".join(slow) or "none") + ". Power is what the modelled GPU draws at the frame rate it "
             "reaches (the target when a frame meets its deadline, else its own lower rate), so it never "
             "exceeds the GPU's full-speed power."]
    mx = next((s for s in presets if s.mode == "max"), None)
    if mx is not None and not mx.real_time:
        notes.append(f"The Max preset is not real time here: it delivers {mx.mean_fps:.3g} fps, not {fps:g}, "
                     "and draws its power at that rate; 'power saved vs Max' compares each mode with a GPU "
                     "that shows fewer frames, and says nothing about energy per frame.")
    return notes


def prediction_notes(rows: Sequence[FrameRow]) -> list[str]:
    """The store's predictions against the measurements, per budget-driven mode: how well the octree's
    camera samples stand for the path's real cameras."""
    notes = []
    for mode in sorted({r.mode for r in rows if r.predicted_error is not None}):
        rs = [r for r in rows if r.mode == mode and r.predicted_error is not None]
        pe = sum(r.predicted_error or 0.0 for r in rs) / len(rs)
        pp = sum(r.predicted_power_w or 0.0 for r in rs) / len(rs)
        me = sum(r.error for r in rs) / len(rs)
        mp = sum(r.power_w for r in rs) / len(rs)
        timed = [r for r in rs if r.predicted_fps is not None and r.fps is not None]
        rate = ""
        if timed:  # the frame rate the store predicted against the one reached (stores with frame times)
            pf = sum(r.predicted_fps or 0.0 for r in timed) / len(timed)
            mf = sum(r.fps or 0.0 for r in timed) / len(timed)
            agree = sum(math.isclose(r.predicted_fps or 0.0, r.fps or 0.0, rel_tol=1e-6) for r in timed)
            rate = (f"; frame rate predicted {pf:.3g} fps, reached {mf:.3g} fps (equal on {agree} of "
                    f"{len(timed)})")
        close = sum(abs((r.predicted_power_w or 0.0) - r.power_w) <= 0.1 * r.power_w for r in rs)
        gap = sum(abs((r.predicted_error or 0.0) - r.error) for r in rs) / len(rs)
        notes.append(f"{MODE_LABELS.get(mode, mode)}: the store predicted mean error {pe:.4f} and power "
                     f"{pp:.3f} W; measured at the path's cameras: {me:.4f} and {mp:.3f} W "
                     f"({len(rs)} frames; power within 10 % on {close}, mean |error predicted - "
                     f"measured| {gap:.4f}){rate}")
    return notes


def read_csv(path: str | Path) -> list[FrameRow]:
    rows = []
    with Path(path).open(newline="", encoding="utf-8") as fh:
        for rec in csv.DictReader(fh):  # columns a CSV of an earlier version lacks are None
            kept, met = rec.get("budget_kept") or "", rec.get("deadline_met") or ""
            pp, pe = rec.get("predicted_power_w") or "", rec.get("predicted_error") or ""
            fps, pf = rec.get("fps") or "", rec.get("predicted_fps") or ""
            rows.append(FrameRow(int(rec["frame"]), float(rec["time_s"]), rec["mode"], float(rec["power_w"]),
                                 float(rec["error"]), rec.get("settings", ""),
                                 None if kept == "" else bool(int(kept)),
                                 None if pp == "" else float(pp), None if pe == "" else float(pe),
                                 None if fps == "" else float(fps), None if met == "" else bool(int(met)),
                                 None if pf == "" else float(pf)))
    return rows


Budget = tuple[str, float]


def budget_list(budget: Budget | Sequence[Budget] | None) -> list[Budget]:
    """One budget ("POWER"/"ERROR", value) or several (a power and an error budget run side by side)."""
    if budget is None:
        return []
    if len(budget) == 2 and isinstance(budget[0], str):
        return [(str(budget[0]), float(budget[1]))]  # type: ignore[arg-type]
    return [(str(m), float(v)) for m, v in budget]  # type: ignore[misc]


def plot_over_time(rows: Sequence[FrameRow], out_dir: str | Path,
                   budget: Budget | Sequence[Budget] | None = None) -> list[Path]:
    """Power and error over time per mode (the paper's Figures 9-11) as PNGs. Needs matplotlib."""
    import matplotlib  # lazy: optional (a stock Blender lacks it), ImportError tells the caller

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: after choosing the non-GUI backend

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    by_mode: dict[str, list[FrameRow]] = {}
    for r in rows:
        by_mode.setdefault(r.mode, []).append(r)
    written = []
    for quantity, ylabel, fname in (("power_w", "power (W)", "power_over_time.png"),
                                    ("error", "error (1 - SSIM)", "error_over_time.png")):
        fig, ax = plt.subplots(figsize=(8, 3.5), dpi=100)
        for mode, rs in by_mode.items():
            rs = sorted(rs, key=lambda r: r.time_s)
            ax.plot([r.time_s for r in rs], [getattr(r, quantity) for r in rs],
                    label=MODE_LABELS.get(mode, mode), linewidth=1.2)
        for b_mode, b_value in budget_list(budget):
            if (b_mode == "POWER" and quantity == "power_w") or (b_mode == "ERROR" and quantity == "error"):
                ax.axhline(b_value, color="k", linestyle="--", linewidth=0.8, label="budget")
        ax.set_xlabel("time (s)")
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        target = out_dir / fname
        fig.savefig(target)
        plt.close(fig)
        written.append(target)
    return written


def main(argv: Sequence[str]) -> int:
    """`report.py plot CSV OUT_DIR`: draw the plots with a Python that has matplotlib."""
    if len(argv) != 3 or argv[0] != "plot":
        sys.stderr.write("usage: report.py plot PER_FRAME.csv OUT_DIR\n")
        return 2
    plot_over_time(read_csv(argv[1]), argv[2])
    return 0



def write_report(out_dir: str | Path, rows: Sequence[FrameRow], *, title: str,
                 budget: Budget | Sequence[Budget], notes: Sequence[str] = (),
                 sections: Sequence[Section] = (), plot: bool = True, table_heading: str = ""
                 ) -> dict[str, Path | str]:
    """Write report.md (Table 3 layout under ``table_heading``, the notes, then ``sections``),
    per_frame.csv and, when matplotlib is importable, the plots. report.md is written once, whole.

    Returns the written paths, plus 'plots_skipped' with the reason when plotting was not possible here.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path | str] = {"csv": write_csv(out_dir / "per_frame.csv", rows)}
    if plot:
        try:
            for p in plot_over_time(rows, out_dir, budget):
                written[p.stem] = p
        except ImportError as err:
            written["plots_skipped"] = f"matplotlib not available in this Python ({err})"
    summaries = summarise(rows)
    budgets = budget_list(budget)
    if not budgets:
        raise ValueError("write_report needs at least one budget")
    stated = ", ".join(f"{m.lower()} <= {v:g} {'W' if m == 'POWER' else '(1 - SSIM)'}" for m, v in budgets)
    lines = [f"# Power budget report: {title}", "",
             f"Budget: {stated}. Error is 1 - SSIM against the maximum-quality "
             "render of the same frame; power is the simulator's at the path's frame rate.", "",
             table3_markdown(summaries, table_heading), "",
             "Files: `per_frame.csv` (every frame and mode), `power_over_time.png`, `error_over_time.png`, "
             "`frames/` (sample frames), `store.json`, `summary.json`.", ""]
    lines += [f"- {n}" for n in [*notes, *prediction_notes(rows)]]
    for section in sections:
        lines += ["", f"## {section.heading}", "", *section.lines]
    report = out_dir / "report.md"
    report.write_text("\n".join(lines) + "\n", encoding="utf-8")
    written["report"] = report
    return written


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
