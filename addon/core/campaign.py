"""The main job as a library: a camera path evaluated the way the power-budget paper's Table 3 is made.

One campaign, two front ends that write the same report folder: ``tools/demo.py`` (``make demo``,
``make report SCENE=...``) and the add-on's *Evaluate Path* (its operator and ``batch evaluate``).
Pure (stdlib + numpy + the service's store, path and option modules; the service's jobs only through a
client: :class:`ServiceClient` or the add-on's local one), so it runs inside the extension.

A campaign measures, through the service's POST /evaluate (:mod:`.evaluate_path`, the REST adapter):

1. the paper's four fixed presets (Max, Max-Mid, Mid-Min, Min) at every evaluated path frame;
2. a power budget: given, or placed ``power_fraction`` of the way between the Min and Max presets'
   measured mean powers (:func:`budget_from_presets`) or between the store frontiers' ends
   (:func:`choose_power_budget`) -- never tuned on the budget modes' results;
3. the store's settings under that power budget and under the error budget, temporal filter included,
   both looked up under the campaign's query options (``CampaignSpec.fps``: the frame-rate target, the
   store's own by default; ``CampaignSpec.priority``: what gives way when no setting keeps both).

Then it writes the report folder (:func:`run`): ``report.md`` (Table 3, notes, then sections: issue 7's
targets, Table 2, time per phase), ``per_frame.csv`` (``frame`` = path index), plots, ``store.json``,
``summary.json`` and ``frames/`` (sample frames as PNG and EXR from POST /render, named by path index).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from service import camera_path, options
from service import store as pareto_store

from . import report
from .campaign_targets import (
    PAPER_TABLE2,
    TARGET_ERROR,
    Preprocessing,
    background_views,
    check_targets,
    table2_markdown,
    table2_row,
    target_lines,
)
from .client import ServiceClient
from .evaluate_path import (
    EvalSpec,
    LookupQuery,
    camera_payload,
    evaluate_path,
    measurement_fps,
    preset_settings,
)
from .playback_logic import PlaybackDriver, validate_budget

try:  # CPU time of finished child processes too (Unix)
    import resource
except ImportError:  # Windows Blender: this process's own CPU time only
    resource = None  # type: ignore[assignment]

CameraPath = camera_path.CameraPath
ParetoStore = pareto_store.ParetoStore

#: Sample frames are this tall by default (width from the path's aspect).
SAMPLE_HEIGHT = 72
#: A sample frame's render may take this long at least, or the client's own timeout if that is longer (the
#: add-on's preference is 60 s by default; a sample at a large --sample-resolution takes minutes).
SAMPLE_TIMEOUT_S = 300.0

#: ``progress(pass_label, renders_done, renders_total)``; the counts run over the whole campaign.
Progress = Callable[[str, int, int], None]


# -- small parts ---------------------------------------------------------------------------------------
class SizeError(ValueError, argparse.ArgumentTypeError):
    """A bad ``WxH`` text (a ValueError; argparse prints its message as it is)."""


def parse_size(text: str, minimum: int = 8) -> tuple[int, int]:
    """``"64x36"`` -> (64, 36); both sides at least ``minimum`` pixels."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise SizeError(f"expected WxH like 64x36, got {text!r}") from None
    if w < minimum or h < minimum:
        raise SizeError(f"resolution must be at least {minimum}x{minimum}, got {text!r}")
    return w, h


def size_for_path(path: CameraPath, height: int, width: int | None = None) -> tuple[int, int]:
    """An image ``height`` pixels tall, ``width`` wide or else with the path's (median) aspect, as the
    optimiser sizes its evaluation images (``service.options.eval_resolution``)."""
    return options.eval_resolution(width, height, float(np.median([f.aspect for f in path.frames])))


def frame_step(path_frames: int, about: int) -> int:
    """The step that evaluates about ``about`` evenly spaced path frames (0 or less: every frame)."""
    return 1 if about <= 0 else max(1, math.ceil(path_frames / about))


def sample_picks(path_frames: int, count: int) -> list[int]:
    """``count`` path indices spread evenly from the first frame to the last."""
    if count <= 0:
        return []
    return sorted({round(k * (path_frames - 1) / max(1, count - 1)) for k in range(count)})


def own_cpu_s() -> float:
    """CPU seconds of this process and its finished children."""
    if resource is None:
        return time.process_time()
    r, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime + c.ru_utime + c.ru_stime


class Clock:
    """Wall and CPU time per phase; ``extra_cpu`` adds another process's CPU (a local service)."""

    def __init__(self, extra_cpu: Callable[[], float | None] | None = None) -> None:
        self.phases: list[dict[str, Any]] = []
        self.extra_cpu = extra_cpu
        self.started = self.start()

    def _cpu(self) -> float:
        return own_cpu_s() + ((self.extra_cpu() if self.extra_cpu else None) or 0.0)

    def start(self) -> tuple[float, float]:
        return time.perf_counter(), self._cpu()

    def stop(self, name: str, t: tuple[float, float]) -> dict[str, Any]:
        rec = {"phase": name, "wall_s": round(time.perf_counter() - t[0], 2),
               "cpu_s": round(self._cpu() - t[1], 2)}
        self.phases.append(rec)
        return rec


# -- the campaign's inputs and measurements ------------------------------------------------------------
@dataclass(frozen=True)
class CampaignSpec(LookupQuery):
    """How to evaluate: the service's scene, sizes, frames, budgets and sample frames."""

    scene_id: str
    resolution: tuple[int, int]  # evaluation (preview) size
    profile: str | None = None  # None: the store's hardware profile
    #: Report power for this size (the path's): the store predicts for the path's pixel count.
    power_resolution: tuple[int, int] | None = None
    frame_step: int = 1
    filter_period_s: float = 2.0
    error_budget: float = TARGET_ERROR
    power_budget: float | None = None  # None: automatic (power_budget_from, power_fraction)
    power_budget_from: str = "presets"  # "presets" | "store"
    power_fraction: float = 0.4  # where the paper's Elven Ruins demo put its budget
    samples: int = 3
    sample_resolution: tuple[int, int] | None = None  # None: SAMPLE_HEIGHT tall, the path's aspect
    concurrency: int = 2
    # (the lookup's query options both budget modes run under come from LookupQuery, keyword-only)

    def __post_init__(self) -> None:
        super().__post_init__()
        validate_budget("ERROR", self.error_budget)
        if self.power_budget is not None:
            validate_budget("POWER", self.power_budget)
        if self.power_budget_from not in ("presets", "store"):
            raise ValueError(f"power_budget_from must be presets or store, got {self.power_budget_from!r}")
        if not 0.0 <= self.power_fraction <= 1.0:
            raise ValueError(f"power fraction must be in [0, 1], got {self.power_fraction}")
        if self.frame_step < 1 or self.samples < 0 or self.concurrency < 1:
            raise ValueError("frame_step and concurrency must be >= 1, samples >= 0")


@dataclass
class Measured:
    """The campaign's measurements: rows of every (frame, mode) and the budgets they ran under."""

    rows: list[report.FrameRow]
    frames: list[int]  # evaluated path indices
    power_budget: float
    power_reason: str
    error_budget: float
    error_reason: str

    @property
    def budgets(self) -> dict[str, tuple[str, float]]:
        """Budget-driven mode label -> (budget mode, value)."""
        return {"ours_power": ("POWER", self.power_budget), "ours_error": ("ERROR", self.error_budget)}


def measure(client: ServiceClient, store: ParetoStore, path: CameraPath, spec: CampaignSpec, *,
            progress: Progress | None = None, say: Callable[[str], None] = lambda _t: None) -> Measured:
    """Presets first (the automatic power budget may come from their powers), then both budget modes."""
    frames = list(range(0, len(path), spec.frame_step))
    store.check_fps(spec.fps)  # a target the store cannot answer is refused before anything is rendered
    total = len(frames) * (len(report.PRESET_LEVELS) + 2)
    rows: list[report.FrameRow] = []

    def run_pass(label: str, mode: str, value: float, modes: tuple[str, ...]) -> None:
        es = EvalSpec(scene_id=spec.scene_id, profile=spec.profile or store.profile,
                      resolution=spec.resolution, budget_mode=mode, budget_value=value,
                      filter_period_s=spec.filter_period_s, frame_step=spec.frame_step, modes=modes,
                      power_resolution=spec.power_resolution, **spec.query)
        offset = len(rows)
        tick = None if progress is None else (lambda done, _n: progress(label, offset + done, total))
        part = evaluate_path(client, store, path, es, progress=tick, concurrency=spec.concurrency)
        rows.extend(dataclasses.replace(r, mode=label) if r.mode == "ours" else r for r in part)

    run_pass("presets", "ERROR", spec.error_budget, tuple(report.PRESET_LEVELS))
    if spec.power_budget is not None:
        power_budget, power_reason = spec.power_budget, f"power budget {spec.power_budget:g} W (given)"
    elif spec.power_budget_from == "store":
        power_budget, power_reason = choose_power_budget(store, path, frames, spec.power_fraction, spec.fps)
    else:
        power_budget, power_reason = budget_from_presets(rows, spec.power_fraction)
    error_reason = f"error budget {spec.error_budget:g} (1 - SSIM)"
    say(f"  {power_reason}")
    say(f"  {error_reason}")
    run_pass("ours_power", "POWER", power_budget, ("ours",))
    run_pass("ours_error", "ERROR", spec.error_budget, ("ours",))
    return Measured(rows, frames, power_budget, power_reason, spec.error_budget, error_reason)


# -- budget choice ---------------------------------------------------------------------------------------
def frontier_span(store: ParetoStore, path: CameraPath, frames: Sequence[int], fps: float | None = None
                  ) -> tuple[float, float]:
    """Path averages of the store's cheapest and most accurate predicted power at the given frames (for
    the frame-rate target ``fps``, default the store's)."""
    lo, hi = [], []
    for i in frames:
        f = path.frames[i]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        kw = {"matrix": m, "fov": f.vfov, "aspect": f.aspect, "fps": fps}
        lo.append(store.lookup(m[:3, 3], error_budget=1.0, **kw).power_w)
        hi.append(store.lookup(m[:3, 3], error_budget=0.0, **kw).power_w)
    return float(np.mean(lo)), float(np.mean(hi))


def choose_power_budget(store: ParetoStore, path: CameraPath, frames: Sequence[int], fraction: float,
                        fps: float | None = None) -> tuple[float, str]:
    """A power budget ``fraction`` of the way from the frontiers' cheapest point to their most accurate
    one (each averaged over the evaluated frames); the reason is returned for the report."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"power fraction must be in [0, 1], got {fraction}")
    lo, hi = frontier_span(store, path, frames, fps)
    budget = lo + fraction * (hi - lo)
    return budget, (f"power budget {budget:.3f} W = {fraction:g} of the way from the store frontiers' "
                    f"cheapest point ({lo:.3f} W) to their most accurate one ({hi:.3f} W), path averages "
                    "of the store's predictions")


def budget_from_presets(rows: Sequence[report.FrameRow], fraction: float) -> tuple[float, str]:
    """A power budget ``fraction`` of the way from the Min preset's mean measured power to the Max
    preset's (the paper's Elven Ruins demo put its 10 W budget 0.4 of the way from Min's 6.11 W to Max's
    15.87 W; Sun Temple's 7 W sits at 0.36)."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"power fraction must be in [0, 1], got {fraction}")
    lo = float(np.mean([r.power_w for r in rows if r.mode == "min"]))
    hi = float(np.mean([r.power_w for r in rows if r.mode == "max"]))
    budget = lo + fraction * (hi - lo)
    return budget, (f"power budget {budget:.3f} W = {fraction:g} of the way from the Min preset's mean "
                    f"measured power ({lo:.3f} W) to the Max preset's ({hi:.3f} W) on the evaluated frames")


# -- sample frames, targets, diagnostics --------------------------------------------------------------
def write_samples(client: ServiceClient, store: ParetoStore, path: CameraPath, spec: CampaignSpec,
                  budgets: dict[str, tuple[str, float]], out_dir: Path) -> list[Path]:
    """A few frames (evenly spread) with the Max and Min presets and each budget mode's unfiltered target
    settings, as PNG and EXR rendered by the service: ``frame<path index>_<mode>.<png|exr>``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    resolution = spec.sample_resolution or size_for_path(path, SAMPLE_HEIGHT)
    presets = preset_settings(store)
    written = []
    for i in sample_picks(len(path), spec.samples):
        f = path.frames[i]
        chosen = {"max": presets["max"], "min": presets["min"]}
        for label, (mode, value) in budgets.items():
            chosen[label] = PlaybackDriver(store, 0.0).step(f.matrix_world, f.vfov, f.aspect, f.time, mode,
                                                            value, **spec.query).active_settings
        for label, settings in chosen.items():
            for fmt in ("png", "exr"):
                img = client.render({"scene_id": spec.scene_id, "camera": camera_payload(f, resolution),
                                     "settings": settings, "profile": spec.profile or store.profile,
                                     "fps": measurement_fps(spec.fps, path),
                                     "format": fmt}, timeout_s=max(SAMPLE_TIMEOUT_S, client.timeout_s))
                target = out_dir / f"frame{i:05d}_{label}.{fmt}"
                target.write_bytes(img.data)
                written.append(target)
    return written


# -- the report ------------------------------------------------------------------------------------------
def measurement_sizes(store_text: str, eval_resolution: tuple[int, int],
                      path: CameraPath) -> tuple[tuple[int, int], tuple[int, int]]:
    """(evaluation size, power size) for a campaign on a store: a store priced at a display size is
    measured there, renders and power at that size, so Table 3 checks the figures the store promises; a
    store with preview figures is measured as it was searched (``eval_resolution``), power scaled to the
    path's size."""
    display = ParetoStore.from_json(store_text).figures.display
    if display is not None:
        return display, display
    return eval_resolution, tuple(int(v) for v in path.frames[0].resolution)


def size_note(spec: CampaignSpec, path: CameraPath) -> str:
    """Which size the report's figures belong to, said plainly (a preview figure is never the result)."""
    w, h = spec.resolution
    pw, ph = spec.power_resolution or (w, h)
    rw, rh = path.frames[0].resolution
    fps = measurement_fps(spec.fps, path)
    if (w, h) == (pw, ph):
        where = "the path's own size" if (w, h) == (rw, rh) else (
            f"the display size the store is priced for; the path's own {rw}x{rh} is not measured here")
        return (f"Evaluated at {w}x{h} ({where}): error and power from renders at that size, power asked for "
                f"{fps:g} fps and drawn at the frame rate reached.")
    return (f"Evaluated at {w}x{h} (preview resolution); power is the simulator's for the path's "
            f"{pw}x{ph} asked for {fps:g} fps (static power plus dynamic energy and frame time scaled "
            "by the pixel count, as the store predicts it), drawn at the frame rate reached.")


def lookup_heading(spec: CampaignSpec, store: ParetoStore) -> str:
    """Table 3's heading: the frame-rate target and the priority both budget modes were looked up under."""
    rate = store.check_fps(spec.fps)
    whose = "the store's own" if spec.fps is None else "asked for"
    margin = f", the error budget with a {spec.error_margin:g} margin" if spec.error_margin else ""
    if spec.power_margin:
        margin += f", the power budget with a {100 * spec.power_margin:g} % margin"
    return (f"Table 3: budget modes looked up for {rate:g} fps ({whose}), "
            f"{options.PRIORITY_LABELS[spec.priority].lower()}{margin}")


def lookup_note(spec: CampaignSpec, store: ParetoStore) -> str:
    """What the priority and the margins mean for the budget modes' figures (a note under Table 3)."""
    margin = ""
    if spec.error_margin:
        margin = (f" Error margin {spec.error_margin:g}: the error-budget mode chose among the settings "
                  f"predicted within {spec.error_budget - spec.error_margin:g}; 'budget kept' is measured "
                  f"against {spec.error_budget:g}.")
    if spec.power_margin:
        margin += (f" Power margin {100 * spec.power_margin:g} %: the power-budget mode chose among the "
                   f"settings predicted to draw at most {100 * (1.0 - spec.power_margin):g} % of its budget; "
                   "'budget kept' is measured against the budget itself.")
    return _priority_note(spec, store) + margin


def _priority_note(spec: CampaignSpec, store: ParetoStore) -> str:
    rate = store.check_fps(spec.fps)
    if spec.priority == "budget":
        note = (f"Priority: budget first. Where no stored setting keeps both the budget and {rate:g} fps, "
                "the budget modes keep the budget and miss the frame rate (their fps row shows it); the "
                "power budget is then broken only where nothing keeps it.")
        if store.meta.get("slow_points") == 1:
            note += (f" The store priced max quality alone among the settings that miss {rate:g} fps "
                     "(slow points 1), so there the error-budget mode picks max quality.")
        return note
    return (f"Priority: frame rate first (the default). Where no stored setting keeps both the budget and "
            f"{rate:g} fps, the budget modes keep the frame rate and break the budget.")


def notes(measured: Measured, spec: CampaignSpec, path: CameraPath, store: ParetoStore) -> list[str]:
    """What the report's figures mean: budgets, lookup priority, sizes, frames, presets, 'budget kept'."""
    step, n = spec.frame_step, len(measured.frames)
    fixed = ", ".join(store.meta.get("fixed_parameters") or {}) or "none"
    return [
        measured.power_reason + ".", measured.error_reason + ": issue 7's target error.",
        lookup_note(spec, store),
        size_note(spec, path),
        f"Frames: {n} of {len(path)} path frames evaluated (every {step}th, {step / path.fps:.2f} s apart); "
        f"the temporal filter (T = {spec.filter_period_s:g} s) runs over the evaluated frames in path order. "
        "`frame` in per_frame.csv and in the sample file names is the index into the camera path.",
        "Presets: every searchable parameter at its maximum-quality value (Max), at 3/4 and 1/4 of the way "
        f"from its cheapest value (Max-Mid, Mid-Min) and at its cheapest value (Min); parameters the scene "
        f"cannot exercise are fixed: {fixed}.",
        "Budget kept: measured power <= power budget (Ours, power budget) or measured error <= error "
        "budget (Ours, error budget) on a frame.",
    ]


def sections(targets: dict[str, Any], store: ParetoStore, path: CameraPath, measured: Measured,
             pre: Preprocessing, clock: Clock, samples: Sequence[Path]) -> list[report.Section]:
    """The report's parts after Table 3 and the notes."""
    st, meta = store.stats(), store.meta
    flat, views, share = targets["background_views"], 6 * st["corners"], targets["background_view_frames"]
    diagnostic = (f"Diagnostic: {flat} of the store's {views} corner views have a frontier whose every "
                  f"point has error < 0.001 (they see background only, so every setting looks free there); "
                  f"{100 * share:.0f} % of the evaluated frames look such a view up. Where that share is "
                  "high, the budget modes pick cheap settings the real camera does not tolerate.")
    store_line = (f"Store: {meta.get('evaluations')} renders ({meta.get('cache_hits')} from the evaluation "
                  f"cache), optimiser's own time {meta.get('elapsed_s')} s, executor {meta.get('executor')}, "
                  f"camera sampling {meta.get('view_sampling')}. Views: the optimised camera samples "
                  "(frontiers of their own), as the paper counts them; the other corner faces inherit one. "
                  "Times are on this machine; CPU time counts this process, its finished children and, "
                  "for a local service, the service process with its evaluation workers.")
    pngs = [p for p in samples if p.suffix == ".png"]
    return [
        report.Section("Issue 7 targets on this run", (*target_lines(targets, st["size_bytes"]), "",
                                                       diagnostic)),
        report.Section("Preprocessing next to the paper's Table 2",
                       (table2_markdown([table2_row(pre, store, path), *PAPER_TABLE2]), store_line)),
        report.Section("Time per phase", (
            "| Phase | Wall (s) | CPU (s) |", "|---|---|---|",
            *[f"| {p['phase']} | {p['wall_s']:.1f} | {p['cpu_s']:.1f} |" for p in clock.phases], "",
            "Sample frames (PNG and EXR): " + (", ".join(f"`frames/{p.name}`" for p in pngs) or "none"))),
    ]


def _jsonable(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    return x


# -- the whole campaign ----------------------------------------------------------------------------------
@dataclass
class Outcome:
    """What :func:`run` measured and wrote."""

    measured: Measured
    summaries: list[report.ModeSummary]
    targets: dict[str, Any]
    written: dict[str, Any]  # report.write_report's paths (+ 'plots_skipped' with the reason)
    samples: list[Path] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)  # what summary.json holds


def run(client: ServiceClient, store_text: str, path: CameraPath, spec: CampaignSpec, out_dir: str | Path,
        *, title: str, pre: Preprocessing, clock: Clock | None = None, progress: Progress | None = None,
        say: Callable[[str], None] = lambda _t: None, plot: bool = True) -> Outcome:
    """Measure (phase 'evaluate'), then write the report folder (phase 'report') and summary.json."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    clock = clock or Clock()
    store = ParetoStore.from_json(store_text)
    (out / "store.json").write_text(store_text, encoding="utf-8")
    w, h = spec.resolution
    pw, ph = spec.power_resolution or (w, h)
    n = len(range(0, len(path), spec.frame_step))
    say("== evaluate the path through the service (POST /evaluate)")
    say(f"  {n} of {len(path)} frames (every {spec.frame_step}th, {spec.frame_step / path.fps:.2f} s apart), "
        f"{w}x{h}, " + ("power at that size" if (w, h) == (pw, ph) else f"power scaled to {pw}x{ph}"))
    t = clock.start()
    measured = measure(client, store, path, spec, progress=progress, say=say)
    clock.stop("evaluate", t)

    say("== report")
    t = clock.start()
    samples = write_samples(client, store, path, spec, measured.budgets, out / "frames")
    summaries = report.summarise(measured.rows)
    targets = check_targets(summaries)
    flat, _views, share = background_views(store, path, measured.frames)
    targets.update(background_views=flat, background_view_frames=share)
    profile = spec.profile or store.profile
    fps = measurement_fps(spec.fps, path)
    real_time = report.real_time_notes(summaries, fps, f"on the `{profile}` profile at {pw}x{ph}")
    written = report.write_report(out, measured.rows, title=title, plot=plot,
                                  table_heading=lookup_heading(spec, store),
                                  notes=[*notes(measured, spec, path, store), *real_time],
                                  budget=[("POWER", measured.power_budget), ("ERROR", measured.error_budget)],
                                  sections=sections(targets, store, path, measured, pre, clock, samples))
    clock.stop("report", t)
    clock.stop("total", clock.started)
    summary = {
        "scene": pre.name, "resolution": [w, h], "power_resolution": [pw, ph],
        "path_image_resolution": [int(v) for v in path.frames[0].resolution],
        "frames_evaluated": len(measured.frames), "frame_step": spec.frame_step, "path_frames": len(path),
        "power_budget_w": measured.power_budget, "error_budget": measured.error_budget,
        "budget_choice": measured.power_reason, "store": {**store.stats(), "meta": dict(store.meta)},
        "profile": profile, "fps_target": fps,
        "lookup": {**spec.query, "fps": store.check_fps(spec.fps), "fps_given": spec.fps},
        "real_time_presets": [s.mode for s in summaries if s.mode in report.PRESET_LEVELS and s.real_time],
        "real_time_notes": real_time,
        "summaries": [dataclasses.asdict(s) for s in summaries], "targets": targets,
        "phases": clock.phases, "report": str(written["report"]),
    }
    summary["files"] = sorted({*(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()),
                               "summary.json"})
    (out / "summary.json").write_text(json.dumps(_jsonable(summary), indent=2), encoding="utf-8")
    return Outcome(measured, summaries, targets, written, samples, summary)
