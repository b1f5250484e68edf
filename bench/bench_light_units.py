"""Light units against Cycles: mean brightness of each Blender light type's scene, Cycles vs the simulator.

The scenes (tests/cycles_reference.py) are a diffuse plane and cube under one light made the Blender way;
Cycles renders them on the CPU (diffuse_bounces = 0, no denoising, black world) and the simulator renders
the same light through Light.from_blender at max quality. Prints one row per case: Cycles' and the
simulator's mean linear brightness, their ratio, and the render times. The test suite runs the same
comparison at 32x32 with 64 samples (tests/test_cycles_reference.py). Then the world (a bundled HDRI
with strength 1.5 and a 1.2 rad Z rotation: mean and pixel correlation), the plane and cube lit by that
HDRI alone (its sky and its sun; mean brightness) and an artist's scene (textured
cube, glossy sphere, rough metal floor, area + point + sun lights, HDRI) at 320x180: mean display
luminance ratio and 1-SSIM against Cycles (128 samples, denoised).

    .venv/bin/python bench/bench_light_units.py [--size 96] [--samples 512]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="bench-light-units-"))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
import cycles_reference


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=96, help="image side in pixels")
    ap.add_argument("--samples", type=int, default=512, help="Cycles samples per pixel")
    args = ap.parse_args()
    print(f"{args.size}x{args.size}, Cycles {args.samples} samples, simulator max quality")
    print("| light | Cycles mean | simulator mean | ratio | Cycles s | simulator s |")
    print("|---|---|---|---|---|---|")
    worst = 0.0
    for name in cycles_reference.CASES:
        t0 = time.perf_counter()
        cycles, _ = cycles_reference.cycles_mean(name, args.size, args.samples)
        t1 = time.perf_counter()
        simulated, _ = cycles_reference.simulator_mean(name, args.size)
        t2 = time.perf_counter()
        ratio = simulated / cycles
        worst = max(worst, abs(ratio - 1.0))
        print(f"| {name} | {cycles:.4f} | {simulated:.4f} | {ratio:.4f} | {t1 - t0:.2f} | {t2 - t1:.2f} |",
              flush=True)
    print(f"largest deviation: {100 * worst:.2f} %")
    import numpy as np

    cycles_world = cycles_reference.cycles_world(1.5, 1.2, samples=64)
    simulated_world = cycles_reference.simulator_world(1.5, 1.2)
    corr = np.corrcoef(cycles_world.ravel(), simulated_world.ravel())[0, 1]
    ratio = simulated_world.mean() / cycles_world.mean()
    print(f"world {cycles_reference.WORLD_HDRI} x1.5 turned 1.2 rad: Cycles mean {cycles_world.mean():.4f}, "
          f"simulator {simulated_world.mean():.4f}, ratio {ratio:.4f}, pixel correlation {corr:.4f}")
    for rotation in (0.0, 2.0):
        cycles_lit, _ = cycles_reference.cycles_world_lit(0.5, rotation, args.size, args.samples)
        simulated_lit, _ = cycles_reference.simulator_world_lit(0.5, rotation, args.size)
        print(f"plane and cube lit by {cycles_reference.WORLD_HDRI} x0.5 turned {rotation} rad "
              f"(sky and sun): Cycles mean {cycles_lit:.4f}, simulator {simulated_lit:.4f}, "
              f"ratio {simulated_lit / cycles_lit:.4f}", flush=True)
    t0 = time.perf_counter()
    cycles_artist = cycles_reference.cycles_artist((320, 180), samples=128)
    t1 = time.perf_counter()
    simulated = cycles_reference.simulator_artist((320, 180))
    t2 = time.perf_counter()
    lum_ratio, dissimilarity = cycles_reference.fidelity(cycles_artist, simulated.image)
    print(f"artist scene 320x180: display luminance ratio {lum_ratio:.4f}, 1-SSIM {dissimilarity:.4f} "
          f"(Cycles {t1 - t0:.1f} s, simulator max quality {t2 - t1:.1f} s)")


if __name__ == "__main__":
    main()
