"""A later pricing round at a camera with its reference read from the build's reference store, against
rendering the reference again (``service.display_pricing.references``).

For each scene, evenly spread path frames at the given display size: a first round prices max quality
and ``--first`` random settings (and saves the reference); then a later round of ``--later`` other
settings is priced twice, the in-process designs cleared each time (another worker process): once
rendering the reference again, once reading it. Prints CPU time of the later round both ways, their
ratio, the reference file's size, and whether the figures are the same to the last digit.

    .venv/bin/python bench/bench_references.py teapot chess --size 640x360 --estimator tiles
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_space_steps import built_scene, cameras

from addon.core.campaign import parse_size
from service.display_pricing import DisplayPricing, ReferenceStore, camera, price_camera
from service.params import default_space


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--size", type=parse_size, default=(640, 360))
    ap.add_argument("--estimator", choices=["tiles", "full"], default="tiles")
    ap.add_argument("--cameras", type=int, default=3)
    ap.add_argument("--first", type=int, default=4)
    ap.add_argument("--later", type=int, default=2)
    ap.add_argument("--profile", default="desktop")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    space = default_space()
    counts = [len(p.values) for p in space.parameters]
    pricing = DisplayPricing(args.estimator, seed=args.seed)
    print(f"display {args.size[0]}x{args.size[1]}, {pricing.label('ssim')}, {args.cameras} cameras: a later "
          f"round of {args.later} settings after a first of max quality + {args.first}")
    print("| scene | later round, reference rendered again: CPU s | reference read: CPU s | ratio | "
          "reference file (MB) | same figures |")
    print("|---|---|---|---|---|---|")
    for name in args.scenes:
        scene, path = built_scene(name)
        rng = np.random.default_rng(args.seed)
        again = read = 0.0
        sizes, same = [], True
        for _, cam in cameras(path, args.cameras, args.size):
            first = [space.max_quality_indices()] + [tuple(int(v) for v in rng.integers(0, counts))
                                                     for _ in range(args.first)]
            later = [tuple(int(v) for v in rng.integers(0, counts)) for _ in range(args.later)]

            def price(sets, references, scene=scene, cam=cam):
                return price_camera(scene, cam, sets, space, profile=args.profile, fps=30.0, metric="ssim",
                                    pricing=pricing, references=references)

            with tempfile.TemporaryDirectory() as tmp:
                store = ReferenceStore(tmp)
                camera._DESIGNS.clear()
                price(first, store)
                sizes += [p.stat().st_size / 1e6 for p in Path(tmp).iterdir()]
                figures = []
                for references in (None, store):
                    camera._DESIGNS.clear()
                    t = time.process_time()
                    res = price(later, references)
                    spent = time.process_time() - t
                    if references is None:
                        again += spent
                    else:
                        read += spent
                    figures.append([(e.error, e.power_w, e.frame_time_s, sorted(e.breakdown.items()))
                                    for e in res])
                same &= figures[0] == figures[1]
        print(f"| {name} | {again:.1f} | {read:.1f} | {read / again:.2f} | {np.mean(sizes):.1f} | "
              f"{'yes' if same else 'NO'} |", flush=True)


if __name__ == "__main__":
    main()
