"""A/B of the store's view sampling: six world-axis views against views aimed at what the path sees.

For one scene, builds a store with each ``view_sampling`` (same reduced budget for both: octree depth
0, NSGA-II population 8 x 3 generations, 64x36, power for 1280x720), then for 8 evenly spaced path
frames looks up the error-budget settings (0.02) and measures them at the frame itself. Prints the
store's predicted error, the measured error and power, Max quality's power, the saving and the share
of frames within the budget.

    .venv/bin/python bench/bench_view_sampling.py teapot
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from service.camera_path import CameraPath
from service.eval_cache import EvalCache
from service.evaluation import CameraSpec, Evaluator, load_scene
from service.executors import InProcessExecutor
from service.optimize import OptimizeOptions, optimize_path, resolve_space
from service.params import default_space

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    scene = sys.argv[1] if len(sys.argv) > 1 else "teapot"
    d = REPO / "blend_scenes" / "build" / scene
    path = CameraPath.load(d / "path.json")
    h = load_scene(d / "scene.glb")
    with tempfile.TemporaryDirectory() as tmp, EvalCache(Path(tmp) / "c.sqlite") as cache:
        space = resolve_space(h.get(), default_space(), path, 1)
        ev = Evaluator(h, space, cache=cache, profile="mobile", fps=30.0, threads=1,
                       target_pixels=1280 * 720)
        picks = np.linspace(0, len(path) - 1, 8).round().astype(int)
        for vs in ("axis", "aimed"):
            opt = OptimizeOptions(max_depth=0, population=8, generations=3, eval_height=36, threads=1,
                                  view_sampling=vs, skip_inert=False)
            st = optimize_path(h, path, space, opt, cache=cache, executor=InProcessExecutor())
            rows = []
            for i in picks:
                f = path.frames[int(i)]
                m = np.asarray(f.matrix_world)
                cam = CameraSpec(tuple(m[:3, 3]), tuple(-m[:3, 2]), tuple(m[:3, 1]), f.vfov, 64, 36)
                hit = st.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect, error_budget=0.02)
                mq = ev.evaluate([(cam, space.max_quality_indices())])[0]
                ch = tuple(q.values.index(hit.settings[q.name]) if q.name in hit.settings else q.max_quality
                           for q in space.parameters)
                r = ev.evaluate([(cam, ch)])[0]
                rows.append((hit.error, r.error, r.power_w, mq.power_w))
            a = np.array(rows)
            print(f"{scene} {vs}: pred e {a[:, 0].mean():.4f} meas e {a[:, 1].mean():.4f} "
                  f"P {a[:, 2].mean():.2f} Pmax {a[:, 3].mean():.2f} "
                  f"saved {1 - a[:, 2].mean() / a[:, 3].mean():.1%} "
                  f"frames<=0.02 {np.mean(a[:, 1] <= 0.02):.0%}", flush=True)


if __name__ == "__main__":
    main()
