"""Evaluate a camera path through the service: every frame with the fixed presets (max, max-mid, mid-min,
min) and with the store's budget-driven settings (temporal filter included), as report rows."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from service import camera_path
from service import store as pareto_store
from service.options import QUERY_BY_NAME, check_query

from .client import ServiceClient
from .playback_logic import PlaybackDriver, PlaybackFrame, validate_budget
from .report import PRESET_LEVELS, FrameRow, preset_indices


@dataclass(frozen=True, kw_only=True)
class LookupQuery:
    """The store lookup's query options (``service.options.QUERY_OPTIONS``) a path evaluation runs its
    budget modes under: the frame-rate target (None: the store's own; every mode is then measured at the
    path's rate, else at this one), the priority and the budgets' margins. Keyword-only, so a spec that
    adds it keeps its own positional fields."""

    fps: float | None = None
    priority: str = "frame_rate"
    error_margin: float = 0.0
    power_margin: float = 0.0

    def __post_init__(self) -> None:
        check_query(self.query)

    @property
    def query(self) -> dict[str, Any]:
        """The options as ``ParetoStore.lookup`` keywords (``service.options.check_query``'s)."""
        return {name: getattr(self, name) for name in QUERY_BY_NAME}


@dataclass(frozen=True)
class EvalSpec(LookupQuery):
    scene_id: str
    profile: str
    resolution: tuple[int, int]
    budget_mode: str
    budget_value: float
    filter_period_s: float = 2.0
    frame_step: int = 1
    modes: tuple[str, ...] = ("ours", "max", "max_mid", "mid_min", "min")
    #: Report power for this resolution (the path's) instead of the evaluation image's: the store's
    #: predictions are for the path's pixel count, and at a few hundred pixels static power hides
    #: every difference between settings. The service scales it (POST /evaluate power_resolution), the
    #: way the optimiser predicts it. None keeps the figure for the evaluation image.
    power_resolution: tuple[int, int] | None = None


def measurement_fps(query_fps: float | None, path: camera_path.CameraPath) -> float:
    """The frame rate the service measures power at: the query's frame-rate target, else the path's."""
    return path.fps if query_fps is None else float(query_fps)


def preset_settings(store: pareto_store.ParetoStore) -> dict[str, dict[str, Any]]:
    """Settings (name -> value) of the paper's four fixed presets over the store's parameter space."""
    counts = [len(p.values) for p in store.parameters]
    mq = [p.max_quality for p in store.parameters]
    return {name: store.settings_of(preset_indices(counts, mq, level))
            for name, level in PRESET_LEVELS.items()}


def camera_payload(frame: camera_path.CameraFrame, resolution: tuple[int, int]) -> dict[str, Any]:
    m = np.asarray(frame.matrix_world, dtype=np.float64).copy()
    m[3] = (0.0, 0.0, 0.0, 1.0)
    return {"matrix_world": m.tolist(), "vfov": float(frame.vfov),
            "width": int(resolution[0]), "height": int(resolution[1])}


def budget_kept(mode: str, value: float, power_w: float, error: float) -> bool:
    return power_w <= value if mode == "POWER" else error <= value


def filtered_frames(store: pareto_store.ParetoStore, path: camera_path.CameraPath, numbers: Iterable[int],
                    budget_mode: str, budget_value: float, period_s: float,
                    query: Mapping[str, Any] | None = None) -> dict[int, PlaybackFrame]:
    """What playback shows at the path frames ``numbers`` under a budget and the lookup's query options
    ``query`` (``service.options.QUERY_OPTIONS``; default: the store's frame rate, frame rate first, no
    margin): the playback
    driver stepped
    over *every* path frame up to the last of them, as during playback, so the temporal filter moves at
    its real pace between sampled frames (stepping it over the sampled frames alone would restart a
    transition at nearly every sample and keep the filter near its starting settings)."""
    wanted = set(numbers)
    kwargs = check_query(query or {})
    driver = PlaybackDriver(store, period_s)
    out: dict[int, PlaybackFrame] = {}
    for number in range(max(wanted, default=-1) + 1):
        f = path.frames[number]
        pf = driver.step(f.matrix_world, f.vfov, f.aspect, f.time, budget_mode, budget_value, **kwargs)
        if number in wanted:
            out[number] = pf
    return out


def evaluate_path(client: ServiceClient, store: pareto_store.ParetoStore, path: camera_path.CameraPath,
                  spec: EvalSpec, *, progress: Callable[[int, int], None] | None = None,
                  concurrency: int = 4) -> list[FrameRow]:
    """Rows for every (sampled frame, mode); errors, power and the frame rate reached measured by the
    service, not predicted. A row's ``frame`` is the index into the path.

    The settings of every frame are decided first (the budget-driven mode runs the temporal filter over
    every path frame in order, exactly as playback does: :func:`filtered_frames`); the evaluations then
    go out `concurrency` at a time.
    """
    validate_budget(spec.budget_mode, spec.budget_value)
    presets = preset_settings(store)
    numbers = range(0, len(path), max(1, spec.frame_step))
    shown = filtered_frames(store, path, numbers, spec.budget_mode, spec.budget_value, spec.filter_period_s,
                            spec.query) if "ours" in spec.modes else {}
    Job = tuple[int, camera_path.CameraFrame, str, dict[str, Any], tuple[float, float, float | None] | None]
    jobs: list[Job] = []
    for number in numbers:
        f = path.frames[number]
        for mode in spec.modes:
            predicted = None
            if mode == "ours":
                pf = shown[number]
                settings = pf.active_settings
                # the filter shows frontier points only: the store predicts them, in transition too
                predicted = (pf.predicted_power_w, pf.predicted_error, pf.predicted_fps)
            else:
                settings = presets[mode]
            jobs.append((number, f, mode, settings, predicted))

    def run(job: Job) -> FrameRow:
        number, f, mode, settings, predicted = job
        body = {"scene_id": spec.scene_id, "camera": camera_payload(f, spec.resolution), "settings": settings,
                "profile": spec.profile, "fps": measurement_fps(spec.fps, path)}
        if spec.power_resolution is not None:
            body["power_resolution"] = [int(v) for v in spec.power_resolution]
        res = client.evaluate(body)
        p, e = float(res["power_w"]), float(res["error"])
        kept = budget_kept(spec.budget_mode, spec.budget_value, p, e) if mode == "ours" else None
        pp, pe, pfps = predicted or (None, None, None)
        fps, met = res.get("fps"), res.get("deadline_met")  # a service before frame rates lacks them
        return FrameRow(number, f.time, mode, p, e, _settings_text(settings), kept, pp, pe,
                        None if fps is None else float(fps), None if met is None else bool(met), pfps)

    rows: list[FrameRow] = []
    with ThreadPoolExecutor(max_workers=max(1, concurrency)) as pool:
        for done, row in enumerate(pool.map(run, jobs), start=1):  # map keeps the order
            rows.append(row)
            if progress:
                progress(done, len(jobs))
    return rows


def _settings_text(settings: dict[str, Any]) -> str:
    return ";".join(f"{k}={v}" for k, v in settings.items())
