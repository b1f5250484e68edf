"""What an error budget can pick from a store's frontier at one camera, against what the setting space
holds: the product's own search (NSGA-II at the evaluation size, inert parameters fixed, power judged for
the display size), the points the display pricing keeps of its frontier (``spread_points``) and of the
search's probes that kept up (``kept_up_to_price``), those points
and the whole frontier priced as whole frames at display resolution, and the error-budget pick (the
cheapest priced point within the budget).

    .venv/bin/python bench/bench_frontier_knee.py chess --profile desktop --size 320x180 --eval 64x36 \
        --cameras 4

``--settings`` adds named settings (``name=PARAMETER:VALUE,...`` over Max, in the space's parameter names
and values) priced at the same cameras, and says whether each is on the search's frontier.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from bench_space_steps import _parse_value, built_scene, cameras

from addon.core.campaign import parse_size
from service.display_pricing import DisplayPricing, price_camera
from service.eval_cache import EvalCache
from service.evaluation import Evaluator
from service.nsga import NSGAConfig
from service.octree.builder import kept_up_to_price, spread_points
from service.octree.search import Search
from service.optimize import resolve_space
from service.params import default_space


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--profile", default="desktop")
    ap.add_argument("--size", type=parse_size, default=(320, 180))
    ap.add_argument("--eval", type=parse_size, default=(64, 36))
    ap.add_argument("--cameras", type=int, default=4)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--budget", type=float, default=0.02)
    ap.add_argument("--points", type=int, default=8, help="display points of the meeting tier")
    ap.add_argument("--slow-points", type=int, default=1)
    ap.add_argument("--settings", nargs="*", default=[])
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    t0 = time.time()
    scene, path = built_scene(args.scene)
    space = resolve_space(scene, default_space(), path, args.threads)
    print(f"{args.scene}: search at {args.eval[0]}x{args.eval[1]}, priced at {args.size[0]}x{args.size[1]}, "
          f"profile {args.profile}; fixed {dict(space.fixed_reasons)}; {space.size} settings searched")
    named = []
    for spec in args.settings:
        name, _, body = spec.partition("=")
        fields = {k: _parse_value(v) for k, _, v in (kv.partition(":") for kv in body.split(","))}
        idx = space.indices_of(fields)
        named.append((name, tuple(idx)))
    mq = space.max_quality_indices()
    pricing = DisplayPricing("full")
    totals: dict[str, list[float]] = {}
    for frame, cam in cameras(path, args.cameras, args.size):
        small = dataclasses.replace(cam, width=args.eval[0], height=args.eval[1])
        ev = Evaluator(scene, space, cache=EvalCache(), profile=args.profile, fps=args.fps,
                       threads=args.threads, target_pixels=args.size[0] * args.size[1])
        search = Search(ev, space, NSGAConfig(seed=0), exhaustive_limit=512)
        got = search.run([small], [[]], "root")[0]
        extra = kept_up_to_price(got.points, got.kept_up, args.fps)  # probes priced besides the spread
        front = got.points + extra
        kept = spread_points(got.points, args.points, args.fps, args.slow_points) + extra
        kept_idx = {p[0] for p in kept}
        todo = [p[0] for p in front] + [x for _, x in named if x not in {p[0] for p in front}]
        if mq not in todo:
            todo.insert(0, mq)
        priced = dict(zip(todo, price_camera(scene, cam, todo, space, profile=args.profile, fps=args.fps,
                                             metric="ssim", pricing=pricing, threads=args.threads),
                          strict=True))
        pmax = priced[mq].power_w
        print(f"\nframe {frame}: {len(front)} frontier points ({ev.evaluations} renders at the evaluation "
              "size), "
              f"{len(kept)} kept for display pricing; Max {pmax:.2f} W")
        print("| kept | setting (values off Max) | search error | search power (W) | display error | "
              "display power (W) | saved vs Max |")
        print("|---|---|---|---|---|---|---|")
        for x, e, p, _ in front:
            r = priced[x]
            print(f"| {'yes' if x in kept_idx else ''} | {_label(space, x)} | {e:.4f} | {p:.2f} | "
                  f"{r.error:.4f} | {r.power_w:.2f} | {100 * (1 - r.power_w / pmax):.1f} % |")
        for name, x in named:
            r = priced[x]
            on = "on the frontier" if x in {p[0] for p in front} else "not on the frontier"
            print(f"| {name} ({on}) | {_label(space, x)} | | | {r.error:.4f} | {r.power_w:.2f} | "
                  f"{100 * (1 - r.power_w / pmax):.1f} % |")

        for what, xs in (("kept points", [p[0] for p in kept]), ("whole frontier", [p[0] for p in front]),
                         ("whole frontier + named", todo)):
            x = min((x for x in xs if priced[x].error <= args.budget), key=lambda x: priced[x].power_w)
            r = priced[x]
            saved = 100 * (1 - r.power_w / pmax)
            totals.setdefault(what, []).extend([saved, r.error])
            print(f"error budget {args.budget} from the {what}: {_label(space, x)}: error {r.error:.4f}, "
                  f"{r.power_w:.2f} W, {saved:.1f} % saved")
    print("\nmean over the cameras (saved, error):")
    for what, v in totals.items():
        n = len(v) // 2
        print(f"  {what}: {sum(v[0::2]) / n:.1f} % saved at error {sum(v[1::2]) / n:.4f}")
    print(f"({time.time() - t0:.0f} s)")


def _label(space, x) -> str:
    mqv = space.values_of(space.max_quality_indices())
    return ", ".join(f"{k}={v}" for k, v in space.values_of(x).items() if v != mqv[k]) or "Max"


if __name__ == "__main__":
    main()
