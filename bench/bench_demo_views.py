"""Why the main job meets or misses its targets: the store's view-cube frontiers against frontiers searched
at the path's own cameras.

For a few evenly spaced frames of a scene's path this runs the optimiser's per-camera search (NSGA-II,
the service's defaults: population 24, 25 generations, 64x36, power for the path's resolution) on the
path camera itself, the "oracle" the store approximates with the six axis views of its octree corners,
and prints per frame:

- the power of maximum quality and of the cheapest setting,
- the oracle's saving at error <= 0.02 (the cheapest frontier point within the error budget),
- what the store picks for the same frame under the same error budget: its predicted error and power
  (from the corner view it looks up) and the measured error and power of those settings at the frame.

    .venv/bin/python bench/bench_demo_views.py --scene teapot [--store out/demo/store.json] [--frames 4]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from service.camera_path import CameraPath
from service.eval_cache import EvalCache
from service.evaluation import CameraSpec, Evaluator, load_scene
from service.nsga import NSGAConfig, optimise
from service.params import default_space
from service.store import ParetoStore

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="teapot")
    ap.add_argument("--store", type=Path, default=None,
                    help="the demo's store.json (default: out/demo/ for teapot, else out/SCENE/)")
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--error-budget", type=float, default=0.02)
    ap.add_argument("--population", type=int, default=24)
    ap.add_argument("--generations", type=int, default=25)
    args = ap.parse_args()

    folder = "demo" if args.scene == "teapot" else args.scene
    store_file = args.store or REPO / "out" / folder / "store.json"
    if not store_file.is_file():
        print(f"no store at {store_file}: run `make demo` (or make report SCENE={args.scene}) first; skipped")
        return
    scene_dir = REPO / "blend_scenes" / "build" / args.scene
    path = CameraPath.load(scene_dir / "path.json")
    store = ParetoStore.from_json(store_file.read_text())
    width, height = store.meta["eval_resolution"]
    space = default_space()
    fixed = store.meta.get("fixed_parameters") or {}
    space = space.fix_inert({str(k): str(v) for k, v in fixed.items()})
    handle = load_scene(scene_dir / "scene.glb")
    target_pixels = int(store.meta["power_pixels"])
    with tempfile.TemporaryDirectory() as tmp, EvalCache(Path(tmp) / "cache.sqlite") as cache:
        ev = Evaluator(handle, space, cache=cache, profile=store.profile, fps=store.fps, threads=1,
                       target_pixels=target_pixels)
        n_values = space.free_n_values
        print(f"{args.scene}: {len(path)} frames, {width}x{height}, power for {target_pixels} pixels, "
              f"store {store.stats()['views']} views / depth {store.stats()['depth']}, "
              f"error budget {args.error_budget}")
        blind = {(c, v) for c in range(len(store.corner_positions())) for v in range(6)
                 if float(np.max(store.frontier(c, v).error)) < 1e-3}
        looked = []
        for f in path.frames:
            m = np.asarray(f.matrix_world, dtype=np.float64)
            hit = store.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect, error_budget=0.0)
            looked.append((hit.corner, hit.view) in blind)
        print(f"store views whose whole frontier has error < 0.001 (background only): {len(blind)} of "
              f"{6 * len(store.corner_positions())}; path frames that look such a view up: "
              f"{100 * np.mean(looked):.1f} %")
        print(f"{'frame':>6} {'P max':>7} {'P min':>7} {'e min':>6} | {'oracle P':>8} {'saved':>6} "
              f"{'e':>6} | {'store P':>7} {'pred e':>6} {'meas P':>7} {'meas e':>6} {'saved':>6}")
        picks = np.linspace(0, len(path) - 1, args.frames).round().astype(int)
        totals = []
        for i in picks:
            f = path.frames[int(i)]
            m = np.asarray(f.matrix_world, dtype=np.float64)
            cam = CameraSpec.from_matrix(m, f.vfov, width, height)

            def evaluate(batch: list[tuple[int, ...]], cam: CameraSpec = cam) -> np.ndarray:
                full = [space.expand(x) for x in batch]
                res = ev.evaluate([(cam, x) for x in full])
                return np.asarray([(r.error, r.power_w) for r in res])

            mq = space.restrict(space.max_quality_indices())
            lo = space.restrict(space.min_quality_indices())
            archive = optimise(evaluate, n_values, NSGAConfig(args.population, args.generations, seed=int(i)),
                               initial=[mq, lo], exhaustive_limit=512)
            front = archive.frontier()
            (_, p_max), (e_min, p_min) = evaluate([mq])[0], evaluate([lo])[0]
            ok = [(x, e, p) for x, e, p in front if e <= args.error_budget]
            _, e_or, p_or = min(ok, key=lambda t: t[2])
            hit = store.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect,
                               error_budget=args.error_budget)
            chosen = tuple(p.values.index(hit.settings[p.name]) if p.name in hit.settings else p.max_quality
                           for p in space.parameters)
            meas = ev.evaluate([(cam, chosen)])[0]
            totals.append((p_max, p_or, e_or, meas.power_w, meas.error))
            print(f"{i:>6} {p_max:7.3f} {p_min:7.3f} {e_min:6.3f} | {p_or:8.3f} {1 - p_or / p_max:6.1%} "
                  f"{e_or:6.4f} | {hit.power_w:7.3f} {hit.error:6.4f} {meas.power_w:7.3f} {meas.error:6.4f} "
                  f"{1 - meas.power_w / p_max:6.1%}")
        t = np.asarray(totals)
        print(f"{'mean':>6} {t[:, 0].mean():7.3f} {'':>7} {'':>6} | {t[:, 1].mean():8.3f} "
              f"{1 - t[:, 1].mean() / t[:, 0].mean():6.1%} {t[:, 2].mean():6.4f} | {'':>7} {'':>6} "
              f"{t[:, 3].mean():7.3f} {t[:, 4].mean():6.4f} {1 - t[:, 3].mean() / t[:, 0].mean():6.1%}")


if __name__ == "__main__":
    main()
