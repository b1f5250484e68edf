"""Replay a main-job run's budget modes offline with three temporal filters, to see what each costs in
budget kept: the paper's Eq. 8 (each parameter index blended separately: mid-transition settings lie on no
frontier), the filter playback uses (Eq. 8's pace along the frontier: every shown setting is a point of the
frame's frontier that keeps the budget, ``service.store.temporal``, through ``PlaybackDriver``) and no
filter (T = 0).

Reads ``OUT/store.json`` and ``OUT/summary.json`` written by ``python -m tools.demo`` (budgets, frame step),
looks the same path frames up and renders the shown settings where the main job measured them (the
summary's ``resolution``, power for its ``power_resolution``), asked for the path's frame rate. Renders
of the same (frame, settings) are shared between filters: only the frames where they differ cost more.

    .venv/bin/python bench/bench_filter_continuity.py hall out/hall
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from addon.core.playback_logic import PlaybackDriver
from service.camera_path import CameraPath
from service.evaluation import CameraSpec, evaluate, load_scene
from service.params import default_space
from service.store import ParetoStore, TemporalFilter

REPO = Path(__file__).resolve().parent.parent
FILTERS = ("eq8", "frontier", "none")


def shown_settings(store: ParetoStore, path: CameraPath, frames: list[int], mode: str, budget: float,
                   kind: str, period: float) -> list[tuple[int, ...]]:
    """The store's value indices each filter shows on each frame."""
    if kind == "frontier" or kind == "none":
        drv = PlaybackDriver(store, period if kind == "frontier" else 0.0)
        return [drv.step(path.frames[i].matrix_world, path.frames[i].vfov, path.frames[i].aspect,
                         path.frames[i].time, mode.upper(), budget).active_indices for i in frames]
    filt = TemporalFilter(period)
    out = []
    for i in frames:
        f = path.frames[i]
        m = np.asarray(f.matrix_world)
        kw = {"power_budget": budget} if mode == "power" else {"error_budget": budget}
        hit = store.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect, **kw)
        out.append(filt.update(hit.indices, f.time))  # Eq. 8: no allowed points
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("out", type=Path, help="the demo's output folder (store.json, summary.json)")
    ap.add_argument("--period", type=float, default=2.0, help="filter T (s; the demo's default 2)")
    ap.add_argument("--threads", type=int, default=None, help="tracer threads per render")
    args = ap.parse_args()
    store = ParetoStore.from_json((args.out / "store.json").read_text())
    summary = json.loads((args.out / "summary.json").read_text())
    period = float(args.period)
    d = REPO / "blend_scenes" / "build" / args.scene
    path = CameraPath.load(d / "path.json")
    scene = load_scene(d / "scene.glb")
    space = default_space()
    frames = list(range(0, len(path), int(summary["frame_step"])))
    (w, h), (pw, ph) = summary["resolution"], summary["power_resolution"]
    print(f"{args.scene}: {len(frames)} frames, T = {period:g} s, power budget "
          f"{summary['power_budget_w']:.3f} W, error budget {summary['error_budget']:g}; rendered at "
          f"{w}x{h}, power for {pw}x{ph} at {path.fps:g} fps")
    print("| filter | mode | mean power (W) | mean error | budget kept | frames in transition |")
    print("|---|---|---|---|---|---|")
    budgets = (("power", float(summary["power_budget_w"])), ("error", float(summary["error_budget"])))
    measured: dict[tuple[int, tuple[int, ...]], tuple[float, float]] = {}
    t0 = time.process_time()
    for mode, budget in budgets:
        targets = shown_settings(store, path, frames, mode, budget, "none", period)
        for kind in FILTERS:
            shown = shown_settings(store, path, frames, mode, budget, kind, period)
            errors, powers = [], []
            for i, idx in zip(frames, shown, strict=True):
                key = (i, idx)
                if key not in measured:
                    f = path.frames[i]
                    m = np.asarray(f.matrix_world)
                    chosen = store.settings_of(idx)
                    full = tuple(p.values.index(chosen[p.name]) if p.name in chosen else p.max_quality
                                 for p in space.parameters)
                    cam = CameraSpec(tuple(m[:3, 3]), tuple(-m[:3, 2]), tuple(m[:3, 1]), f.vfov, w, h)
                    r = evaluate(scene, cam, full, space, fps=path.fps, target_pixels=pw * ph,
                                 threads=args.threads)
                    measured[key] = (r.error, r.power_w)
                e, p = measured[key]
                errors.append(e)
                powers.append(p)
            e, p = np.asarray(errors), np.asarray(powers)
            kept = np.mean(p <= budget) if mode == "power" else np.mean(e <= budget)
            moving = sum(a != b for a, b in zip(shown, targets, strict=True))
            print(f"| {kind} | {mode} | {p.mean():.3f} | {e.mean():.4f} | {kept:.1%} | {moving} |",
                  flush=True)
    print(f"({len(measured)} renders, {time.process_time() - t0:.0f} CPU-s in this process)")


if __name__ == "__main__":
    main()
