"""A/B of the store's camera samples: the paper's view cubes (axis or aimed) against path sampling.

For one scene, builds a store with each chosen ``view_sampling`` under the same NSGA-II budget (64x36,
power for the path's 1280x720), then for evenly spaced path frames looks up the settings under the
error budget (0.02) and under a power budget (0.4 of the way from the Min preset's mean power to the Max
preset's, measured at the same frames) and measures them at the frame itself, without the temporal
filter. Prints, per sampling: build time, renders, depth, samples, store size; then predicted and
measured error / power, the saving against Max, the share of frames within the budget and, under the
power budget, Min's mean error over ours.

    .venv/bin/python bench/bench_view_sampling.py teapot --sampling path aimed --max-depth-paper 1
    .venv/bin/python bench/bench_view_sampling.py chess --sampling path --frames 40
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from service.camera_path import CameraPath
from service.eval_cache import EvalCache
from service.evaluation import CameraSpec, Evaluator, load_scene
from service.executors import ProcessPoolExecutor
from service.optimize import OptimizeConfig, optimize_path, resolve_space
from service.params import default_space

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", nargs="?", default="teapot")
    ap.add_argument("--sampling", nargs="+", default=["path", "aimed"], choices=("path", "aimed", "axis"))
    ap.add_argument("--max-depth-paper", type=int, default=1, help="octree depth of axis/aimed stores")
    ap.add_argument("--path-resolution", type=float, default=0.25)
    ap.add_argument("--guard-frames", type=int, default=2)
    ap.add_argument("--population", type=int, default=24)
    ap.add_argument("--generations", type=int, default=25)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    d = REPO / "blend_scenes" / "build" / args.scene
    path = CameraPath.load(d / "path.json")
    h = load_scene(d / "scene.glb")
    picks = np.linspace(0, len(path) - 1, args.frames).round().astype(int)
    with tempfile.TemporaryDirectory() as tmp, EvalCache(Path(tmp) / "c.sqlite") as cache, \
            ProcessPoolExecutor(args.workers) as ex:
        space = resolve_space(h.get(), default_space(), path, 1)
        ev = Evaluator(h, space, cache=cache, executor=ex, profile="mobile", fps=30.0, threads=1,
                       target_pixels=1280 * 720)
        cams = []
        for i in picks:
            f = path.frames[int(i)]
            m = np.asarray(f.matrix_world)
            cams.append(CameraSpec.from_matrix(m, f.vfov, 64, 36))
        mq = ev.evaluate([(c, space.max_quality_indices()) for c in cams])
        mn = ev.evaluate([(c, space.min_quality_indices()) for c in cams])
        p_max = float(np.mean([r.power_w for r in mq]))
        p_min = float(np.mean([r.power_w for r in mn]))
        e_min = float(np.mean([r.error for r in mn]))
        power_budget = p_min + 0.4 * (p_max - p_min)
        print(f"{args.scene}: {len(picks)} frames, Max {p_max:.2f} W, Min {p_min:.2f} W at error "
              f"{e_min:.4f}; "
              f"error budget 0.02, power budget {power_budget:.2f} W; NSGA-II {args.population} x "
              f"{args.generations}, {args.workers} worker processes", flush=True)
        print("| sampling | build (s) | renders | depth | samples | store KB | mode | predicted | measured "
              "| saved vs Max | frames within budget | Min error / ours |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for vs in args.sampling:
            depth = 6 if vs == "path" else args.max_depth_paper
            opt = OptimizeConfig(max_depth=depth, population=args.population, generations=args.generations,
                                  eval_height=36, threads=1, view_sampling=vs, skip_inert=False,
                                  path_resolution=args.path_resolution, guard_frames=args.guard_frames)
            t0 = time.perf_counter()
            st = optimize_path(h, path, space, opt, cache=cache, executor=ex)
            build_s = time.perf_counter() - t0
            stats = st.stats()
            head = (f"| {vs} | {build_s:.0f} | {st.meta['evaluations']} | {stats['depth']} | "
                    f"{stats['unique_frontiers']} | {stats['size_bytes'] / 1024:.1f} |")
            for mode, kw in (("error", {"error_budget": 0.02}), ("power", {"power_budget": power_budget})):
                hits = []
                for i in picks:
                    f = path.frames[int(i)]
                    m = np.asarray(f.matrix_world)
                    hits.append(st.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect, **kw))
                chosen = [tuple(q.values.index(hh.settings[q.name]) for q in space.parameters) for hh in hits]
                rs = ev.evaluate(list(zip(cams, chosen, strict=True)))
                me = np.array([r.error for r in rs])
                mp = np.array([r.power_w for r in rs])
                saved = 1 - mp.mean() / p_max
                if mode == "error":
                    pred = np.mean([hh.error for hh in hits])
                    print(f"{head} error | e {pred:.4f} | e {me.mean():.4f} (max {me.max():.4f}) | "
                          f"{saved:.1%} | {np.mean(me <= 0.02):.0%} | |", flush=True)
                else:
                    pred = np.mean([hh.power_w for hh in hits])
                    kept = np.mean(mp <= power_budget)
                    print(f"{head} power | {pred:.2f} W | {mp.mean():.2f} W, e {me.mean():.4f} | "
                          f"{saved:.1%} | "
                          f"{kept:.0%} | {e_min / max(me.mean(), 1e-9):.1f}x |", flush=True)


if __name__ == "__main__":
    main()
