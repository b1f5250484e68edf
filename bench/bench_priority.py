"""What the slow tier costs and what putting the budget first buys, on the main job's store.

Optimises one scene as the main job does (``tools.demo.job_request``: the service defaults plus the
demo's stated display size and points, or the options given; in this process, one evaluation at a
time) twice on one search cache: once pricing at display resolution each frontier's meeting-tier
points only (as before the slow tier, ``display_points`` of them), once with the slow tier's points
too (now: up to as many again, spread along it; until then its two ends only). The display pricing
starts afresh for each (its cache entries and camera designs dropped in between), so its CPU seconds
compare; the searches are the same (the second one is answered from the
cache). Then, along the path (every ``--stride``-th frame), the store's predictions under the error
budget for both priorities: the share of frames whose chosen setting keeps the budget, the share that
keeps up with the frame rate, the mean frame rate reached and the mean power.

    .venv/bin/python bench/bench_priority.py --scene chess --stride 10
    .venv/bin/python bench/bench_priority.py --scene teapot --population 8 --generations 6
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from service.camera_path import CameraPath  # noqa: E402
from service.display_pricing import DisplayPricer  # noqa: E402
from service.display_pricing import camera as pricing_camera  # noqa: E402
from service.eval_cache import EvalCache  # noqa: E402
from service.evaluation import SceneHandle  # noqa: E402
from service.executors import InProcessExecutor  # noqa: E402
from service.jobs import build_space, spec_options  # noqa: E402
from service.octree import builder  # noqa: E402
from service.optimize import OptimizeConfig, optimize_path  # noqa: E402
from service.store import ParetoStore, split_by_rate  # noqa: E402
from tools import demo  # noqa: E402


class PricingClock:
    """CPU seconds and settings of every display-pricing call (wraps ``DisplayPricer.price``)."""

    def __init__(self) -> None:
        self.cpu_s = 0.0
        self.settings = 0
        self._price = DisplayPricer.price

    def install(self) -> None:
        clock = self

        def price(pricer: DisplayPricer, requests: Any) -> Any:
            c0 = time.process_time()
            out = clock._price(pricer, requests)
            clock.cpu_s += time.process_time() - c0
            clock.settings += sum(len(xs) for _, xs in requests)
            return out

        DisplayPricer.price = price  # type: ignore[method-assign]


SPREAD = builder.spread_points  # the display points now: the meeting tier's spread and the slow tier's


def meeting_only(points: list[tuple[Any, ...]], k: int, fps: float | None = None) -> list[tuple[Any, ...]]:
    """The display points as before the slow tier: the meeting tier's spread alone."""
    return SPREAD(split_by_rate(points, fps)[0], k)


def forget_display_pricing(cache: EvalCache) -> None:
    """Drop the display-resolution entries and camera designs, keep the search's."""
    with cache._lock:
        cache._db.execute("DELETE FROM evaluations WHERE metric LIKE '%display=%'")
    pricing_camera._DESIGNS.clear()


def predictions(store: ParetoStore, path: CameraPath, stride: int, budget: float, priority: str
                ) -> dict[str, float]:
    kept, meets, fps, power = [], [], [], []
    for f in path.frames[::stride]:
        m = np.asarray(f.matrix_world, dtype=np.float64)
        hit = store.lookup(m[:3, 3], matrix=m, fov=f.vfov, aspect=f.aspect, error_budget=budget,
                           priority=priority)
        kept.append(hit.error <= budget)
        meets.append(bool(hit.meets_fps))
        fps.append(hit.fps)
        power.append(hit.power_w)
    return {"frames": len(kept), "kept": float(np.mean(kept)), "meets": float(np.mean(meets)),
            "fps": float(np.mean(fps)), "power": float(np.mean(power))}


def main() -> None:
    ap = demo.parser()
    ap.description = __doc__
    ap.add_argument("--stride", type=int, default=10, help="every this many path frames looked up")
    ap.add_argument("--now-only", action="store_true",
                    help="skip the run pricing the meeting tier only (just the store and its predictions)")
    args = ap.parse_args()
    scene_dir, _ = demo.build_scene(args.scene, skip=args.skip_build)
    path = CameraPath.from_dict(json.loads((scene_dir / "path.json").read_text()))
    request = demo.job_request(args)
    spec = {"options": request.options}
    config = OptimizeConfig(**spec_options(spec), profile=request.profile, fps=path.fps, threads=1)
    handle = SceneHandle(path=scene_dir / "scene.rbscene", self_contained=True)
    cache = EvalCache(None)
    clock = PricingClock()
    clock.install()
    runs: dict[str, tuple[ParetoStore, float, int, float]] = {}
    variants = [("meeting tier only (before)", meeting_only), ("+ slow tier spread (now)", SPREAD)]
    for label, points in variants[1:] if args.now_only else variants:
        builder.spread_points = points  # type: ignore[assignment]
        forget_display_pricing(cache)
        clock.cpu_s, clock.settings = 0.0, 0
        c0 = time.process_time()
        store = optimize_path(handle, path, build_space(spec), config, cache=cache,
                              executor=InProcessExecutor())
        runs[label] = (store, clock.cpu_s, clock.settings, time.process_time() - c0)
    builder.spread_points = SPREAD  # type: ignore[assignment]
    before, now = runs[variants[0][0]][0] if not args.now_only else None, runs[variants[1][0]][0]
    print(f"{args.scene}: {len(path.frames)} frames at {path.frames[0].resolution}, store priced at "
          f"{now.meta['figures_resolution']} for {path.fps:g} fps, display_points {config.display_points}")
    print("| display pricing | frontiers | with a slow tier | points | settings priced | pricing CPU s | "
          "run CPU s | store KB |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for label, (store, cpu, priced, total) in runs.items():
        slow = sum(f.tiers(store.fps)[1] is not None for f in store.frontiers)
        st = store.stats()
        print(f"| {label} | {st['unique_frontiers']} | {slow} | {st['frontier_points']} | {priced} | "
              f"{cpu:.1f} | {total:.1f} | {st['size_bytes'] / 1024:.1f} |")
    if before is not None:  # a slow end that meets the rate at display resolution joins the meeting tier
        changed = [(a, b.meeting(now.fps)) for a, b in zip(before.frontiers, now.frontiers, strict=True)
                   if a.meeting(before.fps).packed.tolist() != b.meeting(now.fps).packed.tolist()]
        better = sum(float(b.error.min()) < float(a.meeting(before.fps).error.min()) for a, b in changed)
        print(f"meeting tiers that differ: {len(changed)} of {len(now.frontiers)} ({better} reaching a lower "
              "error: a slow end of the search that keeps up at display resolution)")
    print(f"\nerror budget {args.error_budget}, every {args.stride}th path frame (predictions of the store "
          "with the slow tier):")
    print("| priority | frames | budget kept | keeps up with the frame rate | mean fps reached | "
          "mean power W |")
    print("|---|---:|---:|---:|---:|---:|")
    for priority in ("frame_rate", "budget"):
        p = predictions(now, path, args.stride, args.error_budget, priority)
        print(f"| {priority} | {p['frames']} | {100 * p['kept']:.1f} % | {100 * p['meets']:.1f} % | "
              f"{p['fps']:.1f} | {p['power']:.3f} |")


if __name__ == "__main__":
    main()
