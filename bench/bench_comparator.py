"""Compute-on-demand comparator (thesis ch. 4) on the closest-hit comparisons of real scenes.

Every closest-hit distance comparison of a render (candidate t against the current best t, the test a
24-bit comparator in the intersection unit performs) is binned by its compute chain (bits examined after
the first one); the histogram is priced with thesis Table 4.1 for a synchronous and an asynchronous
comparator. Thesis: 7.3 bits on average for z-buffer tests of a game frame, async energy ~1/4 of sync.

A ray's first candidate is compared against +inf (no hit yet), which resolves in the first bit or two; the
z-buffer tests of the thesis compare against a stored depth. So a second histogram from the same primary
rays (per-ray traversal, sim_core.streaming) keeps only the comparisons against a finite best distance.

Run: .venv/bin/python bench/bench_comparator.py [--width 640] [--scenes DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from bench_adaptive import SCENES, cameras, ensure_scenes
from sim_core.energy import comparator_stats
from sim_core.streaming import traverse

from sim_core import RenderSettings, Scene, load_profile, price, render

DEFAULT_SCENES = Path(__file__).resolve().parent.parent / "blend_scenes" / "build"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--scenes", type=Path, default=DEFAULT_SCENES)
    args = ap.parse_args()
    ensure_scenes(args.scenes, SCENES)
    prof = load_profile("mobile")
    print(f"## Closest-hit comparator, {args.width} px wide, default settings (1 spp, depth 2), frame 0")
    print("| scene | comparisons | avg chain (all) | async/sync E (all) | P(chain <= 8) | "
          "avg chain (finite best) | async/sync E (finite best) | async/sync delay (finite) |")
    print("|---|---|---|---|---|---|---|---|")
    for name in SCENES:
        scene = Scene.from_gltf(args.scenes / name / "scene.glb")
        cam = cameras(args.scenes / name / "path.json", args.width, 1)[0]
        r = render(scene, cam, RenderSettings(), cache=prof.cache)
        rep = price(r, prof, 30, scene=scene)
        c = rep.comparator
        h = c.histogram
        o, d = cam.primary_rays()
        _, _, tr = traverse(scene, np.asarray(o).reshape(-1, 3), np.asarray(d).reshape(-1, 3), "per_ray")
        fin = comparator_stats(np.array(tr["compare_finite"], dtype=np.int64))
        print(f"| {name} | {c.comparisons} | {c.average_chain_length:.2f} | {c.async_to_sync_energy:.3f} | "
              f"{h[:9].sum() / max(h.sum(), 1):.2f} | {fin.average_chain_length:.2f} | "
              f"{fin.async_to_sync_energy:.3f} | {fin.async_delay_s / max(fin.sync_delay_s, 1e-30):.2f} |")


if __name__ == "__main__":
    main()
