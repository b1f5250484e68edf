"""Replay a main-job run's budget modes offline with several temporal filters, to see what each costs:
the paper's Eq. 8 (each parameter index blended separately: mid-transition settings lie on no frontier),
the previous filter along the frontier (Eq. 8's blend of value indices, then the allowed point nearest to
it in index space, every transition lasting T; kept here as a reference), the filter playback uses (an
even pace in predicted error among the allowed points, a move across their whole error span in T and a
shorter one in less, ``service.store.temporal``, through ``PlaybackDriver``) and no filter (T = 0).
The allowed points are the frame's frontier points that keep the budget
(``ParetoStore.budget_points``).

Reads ``OUT/store.json`` and ``OUT/summary.json`` written by ``python -m tools.demo`` (budgets, frame
step). Two ways:

``--predicted``: no renders. Every path frame in order (as playback steps), the store's predictions of
the shown settings: mean predicted error and power, frames predicted over the budget while the target
keeps it, and how smoothly the shown settings move (value-index L1 change and predicted-error change per
frame, frames with a change, frames in transition).

    .venv/bin/python bench/bench_filter_continuity.py chess out/chess --predicted

Default: the summary's evaluated frames (the filter still stepped over every frame before them), the shown
settings rendered where the main job measured them (the summary's ``resolution``, power for its
``power_resolution``), asked for the path's frame rate. Renders of the same (frame, settings) are shared
between filters: only the frames where they differ cost more.

    .venv/bin/python bench/bench_filter_continuity.py hall out/hall
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from addon.core.campaign import choose_power_budget
from addon.core.playback_logic import PlaybackDriver
from service.camera_path import CameraPath
from service.evaluation import CameraSpec, evaluate, load_scene
from service.params import default_space
from service.store import ParetoStore, TemporalFilter
from service.store.lookup import FrontierPoint

REPO = Path(__file__).resolve().parent.parent
FILTERS = ("none", "index", "error", "eq8")
LABELS = {"none": "no filter (T = 0)", "index": "before: nearest in index space to Eq. 8's blend",
          "error": "now: even pace in predicted error, whole span in T",
          "eq8": "Eq. 8 (per-index blend, off the frontier)"}
Indices = tuple[int, ...]


def _l1(a: Sequence[float], b: Sequence[float]) -> float:
    return sum(abs(x - y) for x, y in zip(a, b, strict=True))


class IndexNearestFilter:
    """The previous rule, for comparison: Eq. 8's unrounded blend of value indices, then the allowed point
    nearest to it (L1), never further (L1) from the target than the point shown on the previous frame."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.old: Indices | None = None
        self.target: Indices | None = None
        self.shown: Indices | None = None
        self.t0 = 0.0
        self.last_t = -math.inf

    def update(self, target: Indices, now: float, allowed: Sequence[Indices]) -> Indices:
        if self.target is None or now < self.last_t:
            self.old, self.target, self.t0 = None, target, now
        elif target != self.target:
            self.old, self.target, self.t0 = self.shown, target, now
        self.last_t = now
        if self.old is None or self.period_s == 0 or now - self.t0 >= self.period_s:
            shown = target
        else:
            a = (now - self.t0) / self.period_s
            point = [(1 - a) * o + a * n for o, n in zip(self.old, target, strict=True)]
            bound = math.inf if now == self.t0 or self.shown is None else _l1(self.shown, target)
            best, key = target, (math.inf, math.inf)
            for c in allowed:
                d = _l1(c, target)
                if d <= bound and (_l1(c, point), d) < key:
                    best, key = c, (_l1(c, point), d)
            shown = best
        if shown == target:
            self.old = None
        self.shown = shown
        return shown


def replay(store: ParetoStore, path: CameraPath, last: int, mode: str, budget: float, period: float,
           ) -> tuple[list[Indices], dict[str, list[Indices]], list[dict[Indices, FrontierPoint]]]:
    """Targets, each filter's shown settings and the allowed points of path frames 0..last."""
    drivers = {"none": PlaybackDriver(store, 0.0), "error": PlaybackDriver(store, period)}
    index, eq8 = IndexNearestFilter(period), TemporalFilter(period)
    kw = {"power_budget": budget} if mode == "power" else {"error_budget": budget}
    targets: list[Indices] = []
    shown: dict[str, list[Indices]] = {k: [] for k in FILTERS}
    allowed: list[dict[Indices, FrontierPoint]] = []
    for i in range(last + 1):
        f = path.frames[i]
        m = np.asarray(f.matrix_world)
        hit = store.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect, **kw)
        points = {p.indices: p for p in store.budget_points(hit)}
        targets.append(hit.indices)
        allowed.append(points)
        for kind, drv in drivers.items():
            pf = drv.step(f.matrix_world, f.vfov, f.aspect, f.time, mode.upper(), budget)
            assert pf.target_indices == hit.indices
            shown[kind].append(pf.active_indices)
        shown["index"].append(index.update(hit.indices, f.time, list(points)))
        shown["eq8"].append(eq8.update(hit.indices, f.time))  # no allowed points: Eq. 8
    return targets, shown, allowed


def predicted_table(store: ParetoStore, path: CameraPath, mode: str, budget: float, period: float) -> None:
    targets, shown, allowed = replay(store, path, len(path) - 1, mode, budget, period)
    n = len(targets)
    print(f"\n{mode} budget {budget:.4g}, {n} path frames (every frame), T = {period:g} s; predicted:")
    print("| filter | mean error | mean power (W) | over budget (target keeps it) | off frontier | "
          "frames in transition | frames with a change | index L1 change per frame mean / max | "
          "error change per frame mean / max |")
    print("|---|---|---|---|---|---|---|---|---|")
    for kind in FILTERS:
        seq = shown[kind]
        on = [k for k in range(n) if seq[k] in allowed[k]]
        err = np.array([allowed[k][seq[k]].error for k in on])
        pw = np.array([allowed[k][seq[k]].power_w for k in on])
        target_keeps = [allowed[k][targets[k]].power_w <= budget if mode == "power"
                        else allowed[k][targets[k]].error <= budget for k in on]
        over = sum(bool(keep) and ((p > budget) if mode == "power" else (e > budget))
                   for keep, p, e in zip(target_keeps, pw, err, strict=True))
        steps = [_l1(a, b) for a, b in itertools.pairwise(seq)]
        jumps = [abs(allowed[k + 1][seq[k + 1]].error - allowed[k][seq[k]].error)
                 for k in range(n - 1) if seq[k] in allowed[k] and seq[k + 1] in allowed[k + 1]]
        moving = sum(a != b for a, b in zip(seq, targets, strict=True))
        mean_e = f"{err.mean():.4f}" if len(on) == n else f"({err.mean():.4f} on frontier frames)"
        mean_p = f"{pw.mean():.4f}" if len(on) == n else f"({pw.mean():.4f})"
        print(f"| {LABELS[kind]} | {mean_e} | {mean_p} | {over} | {n - len(on)} | {moving} | "
              f"{sum(s > 0 for s in steps)} | {np.mean(steps):.3f} / {max(steps):g} | "
              f"{np.mean(jumps):.4f} / {max(jumps):.4f} |", flush=True)


def measured_table(args: argparse.Namespace, store: ParetoStore, path: CameraPath, summary: dict,
                   budgets: list[tuple[str, float]], period: float) -> None:
    d = REPO / "blend_scenes" / "build" / args.scene
    scene = load_scene(d / "scene.glb")
    space = default_space()
    frames = list(range(0, len(path), int(summary["frame_step"])))
    (w, h), (pw, ph) = summary["resolution"], summary["power_resolution"]
    print(f"{len(frames)} evaluated frames, rendered at {w}x{h}, power for {pw}x{ph} at {path.fps:g} fps")
    print("| filter | mode | mean power (W) | mean error | budget kept | frames in transition |")
    print("|---|---|---|---|---|---|")
    measured: dict[tuple[int, Indices], tuple[float, float]] = {}
    t0 = time.process_time()
    for mode, budget in budgets:
        targets, shown, _ = replay(store, path, frames[-1], mode, budget, period)
        for kind in FILTERS:
            errors, powers = [], []
            for i in frames:
                key = (i, shown[kind][i])
                if key not in measured:
                    f = path.frames[i]
                    m = np.asarray(f.matrix_world)
                    chosen = store.settings_of(key[1])
                    full = tuple(p.values.index(chosen[p.name]) if p.name in chosen else p.max_quality
                                 for p in space.parameters)
                    cam = CameraSpec.from_matrix(m, f.vfov, w, h)
                    r = evaluate(scene, cam, full, space, fps=path.fps, target_pixels=pw * ph,
                                 threads=args.threads)
                    measured[key] = (r.error, r.power_w)
                e, p = measured[key]
                errors.append(e)
                powers.append(p)
            e, p = np.asarray(errors), np.asarray(powers)
            kept = np.mean(p <= budget) if mode == "power" else np.mean(e <= budget)
            moving = sum(shown[kind][i] != targets[i] for i in frames)
            print(f"| {LABELS[kind]} | {mode} | {p.mean():.3f} | {e.mean():.4f} | {kept:.1%} | {moving} |",
                  flush=True)
    print(f"({len(measured)} renders, {time.process_time() - t0:.0f} CPU-s in this process)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("out", type=Path, help="the demo's output folder (store.json, summary.json)")
    ap.add_argument("--period", type=float, default=2.0, help="filter T (s; the demo's default 2)")
    ap.add_argument("--predicted", action="store_true", help="store predictions over every path frame, "
                    "no renders")
    ap.add_argument("--fraction", type=float, default=None, help="power budget this far from the "
                    "frontiers' cheapest to their most accurate point over all path frames "
                    "(campaign.choose_power_budget) instead of the summary's budget")
    ap.add_argument("--threads", type=int, default=None, help="tracer threads per render")
    ap.add_argument("--store", type=Path, default=None, help="a store's JSON instead of OUT/store.json "
                    "(with --predicted and --fraction, OUT's summary is not needed)")
    args = ap.parse_args()
    store = ParetoStore.from_json((args.store or args.out / "store.json").read_text())
    summary_file = args.out / "summary.json"
    summary = json.loads(summary_file.read_text()) if summary_file.exists() else {}
    path = CameraPath.load(REPO / "blend_scenes" / "build" / args.scene / "path.json")
    if args.fraction is not None:
        power, why = choose_power_budget(store, path, range(len(path)), args.fraction)
        print(why)
    else:
        power = float(summary["power_budget_w"])
    error = float(summary.get("error_budget", 0.02))
    budgets = [("power", power), ("error", error)]
    print(f"{args.scene}: {len(path)} path frames, T = {args.period:g} s, power budget {power:.4f} W, "
          f"error budget {error:g}")
    if args.predicted:
        for mode, budget in budgets:
            predicted_table(store, path, mode, budget, float(args.period))
    else:
        measured_table(args, store, path, summary, budgets, float(args.period))


if __name__ == "__main__":
    main()
