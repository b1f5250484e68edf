"""Streaming traversal (thesis ch. 3) against per-ray traversal: scene bytes per (triangle x pixel x frame).

For each bundled mesh, 512x512 primary rays and the mirror-reflection rays at their hits (the thesis
streams reflection rays after z-buffered primary visibility) are traced three ways: per-ray with every node
and triangle fetch going to memory (Foley-Sugerman-style GPU traversal, the thesis' 0.52/0.89 B column),
per-ray behind the mobile profile's per-tile cache (our tracer's model), and streamed with conditional
output streams (thesis: 0.022 B for the TT in Sponza, 371k triangles, 512x512). Closest hits are checked to
be identical. Stream traffic (ray ids, entry distances, ray records) is reported separately: the thesis'
figure counts scene data; with on-chip stream buffers the stream traffic does not reach DRAM.

Run: .venv/bin/python bench/bench_streaming.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from sim_core.energy import load_profile
from sim_core.loaders import load_gltf, load_obj
from sim_core.scene import Scene
from sim_core.streaming import compare_traversal, pinhole_rays, reflection_rays

MODELS = Path(__file__).resolve().parent.parent / "assets" / "models"
SCENES = Path(__file__).resolve().parent.parent / "blend_scenes" / "build"
SIZE = 512


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=Path, default=SCENES, help="built blend_scenes (lab, valley if present)")
    args = ap.parse_args()
    cache = load_profile("mobile").cache
    print(f"## Bytes per (triangle x pixel x frame), {SIZE}x{SIZE}, mobile cache {cache}")
    print("| scene | triangles | rays | per-ray, no cache | per-ray, per-tile cache | streaming (scene) | "
          "streaming (+ streams) | per-ray / streaming | avg interior stream | avg leaf stream | same hits |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    total = 0.0
    sources = [(n, MODELS / f"{n}.obj") for n in ("teapot", "spot", "cow", "stanford-bunny")]
    sources += [(n, args.scenes / n / "scene.glb") for n in ("lab", "valley")
                if (args.scenes / n / "scene.glb").exists()]
    for name, path in sources:
        data = load_obj(path) if path.suffix == ".obj" else load_gltf(path)
        scene = Scene.from_scene_data(data)
        lo, hi = (np.array(b) for b in scene.bounds)
        c, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
        o, d = pinhole_rays(c + np.array([0.2, -0.9, 0.35]) * diag, c, [0, 0, 1], 0.7, SIZE, SIZE, tile=16)
        t, p = scene.intersect(o, d)
        ro, rd = reflection_rays(data.positions, data.triangles, o, d, t, p)
        for label, (oo, dd) in (("primary", (o, d)), ("reflection", (ro, rd))):
            t0 = time.perf_counter()
            cmp = compare_traversal(scene, oo, dd, pixels=SIZE * SIZE, cache=cache, group_size=256)
            dt = time.perf_counter() - t0
            a = cmp.bytes_per_tri_pixel(cmp.per_ray)
            b = cmp.bytes_per_tri_pixel(cmp.per_ray_cached)
            s = cmp.bytes_per_tri_pixel(cmp.streaming)
            s2 = cmp.bytes_per_tri_pixel(cmp.streaming, include_streams=True)
            print(f"| {name} {label} | {cmp.triangles} | {cmp.rays} | {a:.4g} | {b:.4g} | {s:.4g} | "
                  f"{s2:.4g} | {a / s:.0f}x | {cmp.avg_interior_stream:.1f} | {cmp.avg_leaf_stream:.1f} | "
                  f"{cmp.same_hits} |")
            total += dt
    print(f"\n(traversal time for all batches, three schemes each: {total:.1f} s)")


if __name__ == "__main__":
    main()
