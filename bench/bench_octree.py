"""Octree preprocessing on the real tracer, budget deviation along the path, lookup time, and the effect
of the evaluation resolution on the frontier.

A) For a few (tau_p, tau_e) pairs: preprocessing time, renders, corners, views (optimised / stored),
   store size; then along the path, for a power budget and an error budget, the settings the store picks
   are rendered at the frame's own camera and resolution: mean |predicted - actual| power and error, the
   share of frames within budget, and the power saved against maximum quality.
B) Lookup + temporal filter per query on the built store.
C) Evaluation resolution: exhaustive frontier of one camera at several resolutions, each frontier's
   settings re-rendered at the full resolution and compared with the full-resolution frontier (D_e, D_p
   of Eq. 4-7, normalised as in the octree) against the time per evaluation.

Run: .venv/bin/python bench/bench_octree.py [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_nsga import teapot_scene

from service import nsga
from service.camera_path import CameraPath
from service.eval_cache import EvalCache
from service.evaluation import CameraSpec, Evaluator, SceneHandle, evaluate
from service.executors import InProcessExecutor
from service.octree import frontier_distance
from service.optimize import OptimizeConfig, optimize_path
from service.params import default_space
from service.store import TemporalFilter


def orbit_path(n: int = 24, res: tuple[int, int] = (160, 120)) -> CameraPath:
    """A quarter orbit around the teapot, rising slowly, looking at it."""
    a = np.linspace(-0.9, 0.6, n)
    pos = np.stack([8.0 * np.sin(a), -8.0 * np.cos(a), 3.5 + 1.0 * np.linspace(0, 1, n)], axis=1)
    dirs = np.array([0.0, 0.0, 1.0]) - pos
    return CameraPath.from_positions(pos, dirs, vfov=0.7, resolution=res, fps=12.0)


def frame_camera(f, width: int, height: int) -> CameraSpec:
    return CameraSpec(tuple(f.position), tuple(f.direction), (0.0, 0.0, 1.0), f.vfov, width, height)


def part_a(quick: bool) -> None:
    scene = teapot_scene()
    handle = SceneHandle(scene)
    path = orbit_path(12 if quick else 24)
    sp = default_space().subset(["sampling", "max_depth", "shadow_samples", "resolution_scale", "ao_samples"])
    pairs = ([(0.05, 0.02, 0), (0.01, 0.005, 0), (0.01, 0.005, 2)] if quick else
             [(0.1, 0.04, 0), (0.05, 0.02, 0), (0.01, 0.005, 0), (0.01, 0.005, 1), (0.01, 0.005, 2)])
    w, h = path.frames[0].resolution
    print(f"A) teapot, {len(path)}-frame orbit at {w}x{h}, space {sp.size} settings, evaluation 32x24, "
          f"pop 24 x {8 if quick else 12} gens, max depth 2")
    print(f"{'tau_p W':>8} {'tau_e':>6} {'min d':>5} {'time s':>7} {'renders':>8} {'corners':>8} "
          f"{'views opt/stored':>17} {'KB':>6} | {'budget':>12} {'|dP| W':>8} {'|dE|':>7} "
          f"{'in budget':>9} {'P saved':>8}")
    last_store = None
    for tau_p, tau_e, min_depth in pairs:
        opts = OptimizeConfig(threshold_power_w=tau_p, threshold_error=tau_e, max_depth=2,
                               min_depth=min_depth, population=24,
                               generations=8 if quick else 12, exhaustive_limit=0, eval_width=32,
                               eval_height=24, seed=0)
        t0 = time.perf_counter()
        store = optimize_path(handle, path, sp, opts, cache=EvalCache(), executor=InProcessExecutor())
        dt = time.perf_counter() - t0
        st = store.stats()
        last_store = store
        head = (f"{tau_p:8.3f} {tau_e:6.3f} {min_depth:5d} {dt:7.1f} {store.meta['evaluations']:8d} "
                f"{st['corners']:8d} {store.meta['views_optimised']:>8}/{st['views']:<8} "
                f"{st['size_bytes'] / 1024:6.1f}")
        # actual power/error of the chosen settings at each frame's own camera and resolution
        mq = sp.max_quality_indices()
        p_max = np.mean([evaluate(handle, frame_camera(f, w, h), mq, sp).power_w for f in path.frames])
        for kind, budget in (("power", None), ("error", 0.03)):
            dps, des, ok, pw = [], [], 0, []
            if kind == "power":
                budget = float(np.round(0.5 * (p_max + st_min_power(store)), 3))
            for f in path.frames:
                kw = {"power_budget": budget} if kind == "power" else {"error_budget": budget}
                r = store.lookup(f.position, direction=f.direction, fov=f.vfov, **kw)
                ev = evaluate(handle, frame_camera(f, w, h), r.indices, sp)
                dps.append(abs(ev.power_w - r.power_w))
                des.append(abs(ev.error - r.error))
                pw.append(ev.power_w)
                ok += (ev.power_w <= budget) if kind == "power" else (ev.error <= budget)
            label = f"P<={budget:.3f} W" if kind == "power" else f"E<={budget:.3f}"
            print(f"{head} | {label:>12} {np.mean(dps):8.4f} {np.mean(des):7.4f} "
                  f"{ok / len(path):9.0%} {1 - np.mean(pw) / p_max:8.1%}")
            head = " " * len(head)
    assert last_store is not None
    part_b(last_store, path)


def st_min_power(store) -> float:
    return float(min(fr.power_w.min() for fr in store.frontiers))


def part_b(store, path: CameraPath) -> None:
    n = 20000
    frames = path.frames
    filt = TemporalFilter(2.0)
    t0 = time.perf_counter()
    for i in range(n):
        f = frames[i % len(frames)]
        r = store.lookup(f.position, direction=f.direction, fov=f.vfov, error_budget=0.02)
        filt.update(r.indices, i / 60.0)
    dt = (time.perf_counter() - t0) / n
    print(f"\nB) lookup + temporal filter on the last store: {dt * 1e6:.1f} us per query ({n} queries)")


def part_c(quick: bool) -> None:
    scene = teapot_scene()
    handle = SceneHandle(scene)
    sp = default_space().subset(["sampling", "max_depth", "shadow_samples", "resolution_scale"])
    full = (128, 96) if quick else (256, 192)
    resolutions = [(16, 12), (32, 24), (64, 48)] + ([] if quick else [(128, 96)])

    def cam(wh):
        return CameraSpec((0.0, -9.0, 5.0), (0.0, 9.0, -4.0), (0.0, 0.0, 1.0), 0.7, *wh)

    xs = [sp.expand(x) for x in nsga.enumerate_space(sp.free_n_values)]
    target = full[0] * full[1]

    def frontier(wh):
        ev = Evaluator(handle, sp, cache=EvalCache(), target_pixels=target)
        t0 = time.perf_counter()
        res = ev.evaluate([(cam(wh), x) for x in xs])
        per = (time.perf_counter() - t0) / len(xs)
        F = np.asarray([(r.error, r.power_w) for r in res])
        m = nsga.non_dominated_mask(F)
        return [x for x, k in zip(xs, m, strict=True) if k], F[m], per

    fx, fF, fper = frontier(full)
    print(f"\nC) evaluation resolution, one camera, exhaustive {sp.size} settings, "
          f"reference {full[0]}x{full[1]}")
    print(f"{'resolution':>11} {'ms/eval':>8} {'points':>7} {'D_e':>8} {'D_p W':>8}")
    print(f"{full[0]:>5}x{full[1]:<5} {fper * 1e3:8.2f} {len(fx):7d} {0:8.4f} {0:8.4f}")
    ev_full = Evaluator(handle, sp, cache=EvalCache(), target_pixels=target)
    for wh in resolutions:
        lx, _, per = frontier(wh)
        # project the low-resolution frontier's settings to the full resolution
        proj = np.asarray([(r.error, r.power_w) for r in ev_full.evaluate([(cam(full), x) for x in lx])])
        allp = np.concatenate([proj, fF])
        scale = (max(float(np.ptp(allp[:, 0])), 1e-3), max(float(np.ptp(allp[:, 1])), 1e-3))
        de1, dp1 = frontier_distance(proj, fF, scale)
        de2, dp2 = frontier_distance(fF, proj, scale)
        print(f"{wh[0]:>5}x{wh[1]:<5} {per * 1e3:8.2f} {len(lx):7d} {de1 + de2:8.4f} {dp1 + dp2:8.4f}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--part", choices=("a", "c", "all"), default="all")
    args = ap.parse_args()
    if args.part in ("a", "all"):
        part_a(args.quick)
    if args.part in ("c", "all"):
        part_c(args.quick)


if __name__ == "__main__":
    main()
