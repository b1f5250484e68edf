"""Replay a main-job run's budget modes offline, with Eq. 8's temporal filter and with a continuity-
preferring target choice, to see what the filter costs in budget kept.

Reads ``OUT/store.json`` and ``OUT/summary.json`` written by ``python -m tools.demo`` (power budget,
frame step), looks the same path frames up, runs ``TemporalFilter(T)`` and renders the shown settings
at 64x36 with power for 1280x720 (as the demo's evaluation does; with ``--tolerance 0`` it reproduces the
demo's table). ``--tolerance t > 0``: when the lookup's target changes, take instead, among the new
frontier's points within ``t`` of the optimum (power under the error budget, error under the power
budget), the one nearest (L1 in value indices) to the settings shown at that moment, so that the filter
blends between similar settings. An experiment, not the playback code.

    .venv/bin/python bench/bench_filter_continuity.py hall out/hall --tolerance 0 0.1
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from service.camera_path import CameraPath
from service.evaluation import CameraSpec, evaluate, load_scene
from service.params import default_space
from service.store import LookupResult, ParetoStore, TemporalFilter, unpack_indices

REPO = Path(__file__).resolve().parent.parent


def continuity_target(store: ParetoStore, hit: LookupResult, shown: tuple[int, ...] | None, mode: str,
                      budget: float, tolerance: float) -> tuple[int, ...]:
    if shown is None or tolerance <= 0:
        return tuple(hit.indices)
    fr = store.frontier(hit.corner, hit.view)
    if mode == "power":
        ok = np.flatnonzero(fr.power_w <= budget)
        if not len(ok):
            return tuple(hit.indices)
        best = fr.error[ok].min()
        cand = ok[fr.error[ok] <= best * (1 + tolerance) + 0.002 * tolerance]
    else:
        ok = np.flatnonzero(fr.error <= budget)
        if not len(ok):
            return tuple(hit.indices)
        cand = ok[fr.power_w[ok] <= fr.power_w[ok].min() * (1 + tolerance)]
    idx = [unpack_indices(int(fr.packed[i]), store.n_params) for i in cand]
    return idx[int(np.argmin([sum(abs(a - b) for a, b in zip(x, shown, strict=True)) for x in idx]))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("out", type=Path, help="the demo's output folder (store.json, summary.json)")
    ap.add_argument("--tolerance", type=float, nargs="+", default=[0.0, 0.1])
    ap.add_argument("--period", type=float, default=2.0, help="filter T (s)")
    args = ap.parse_args()
    store = ParetoStore.from_json((args.out / "store.json").read_text())
    summary = json.loads((args.out / "summary.json").read_text())
    d = REPO / "blend_scenes" / "build" / args.scene
    path = CameraPath.load(d / "path.json")
    scene = load_scene(d / "scene.glb")
    space = default_space()
    frames = list(range(0, len(path), int(summary["frame_step"])))
    print(f"{args.scene}: {len(frames)} frames, T = {args.period:g} s, power budget "
          f"{summary['power_budget_w']:.3f} W, error budget {summary['error_budget']:g}")
    print("| tolerance | mode | mean power (W) | mean error | budget kept |")
    print("|---|---|---|---|---|")
    budgets = (("power", float(summary["power_budget_w"])), ("error", float(summary["error_budget"])))
    for tol in args.tolerance:
        for mode, budget in budgets:
            filt, shown = TemporalFilter(args.period), None
            errors, powers = [], []
            for i in frames:
                f = path.frames[i]
                m = np.asarray(f.matrix_world)
                kw = {"power_budget": budget} if mode == "power" else {"error_budget": budget}
                hit = store.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect, **kw)
                shown = filt.update(continuity_target(store, hit, shown, mode, budget, tol), f.time)
                chosen = store.settings_of(shown)
                idx = tuple(p.values.index(chosen[p.name]) if p.name in chosen else p.max_quality
                            for p in space.parameters)
                cam = CameraSpec(tuple(m[:3, 3]), tuple(-m[:3, 2]), tuple(m[:3, 1]), f.vfov, 64, 36)
                r = evaluate(scene, cam, idx, space, target_pixels=1280 * 720)
                errors.append(r.error)
                powers.append(r.power_w)
            e, p = np.asarray(errors), np.asarray(powers)
            kept = np.mean(p <= budget) if mode == "power" else np.mean(e <= budget)
            print(f"| {tol:g} | {mode} | {p.mean():.2f} | {e.mean():.4f} | {kept:.1%} |", flush=True)


if __name__ == "__main__":
    main()
