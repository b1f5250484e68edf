"""Tracer vs Embree on identical rays, one thread: primary and diffuse-bounce rays.

Scenes: the Stanford bunny (69K triangles) and a 3 x 3 grid of bunnies (625K triangles).
Rays: 512 x 512 camera rays; diffuse bounce rays leave the primary hit points (offset 1e-4 of the scene
size along the geometric normal) in cosine-distributed directions. Both tracers get the same float32
arrays; each timing is the median of several interleaved repetitions of the process CPU time (the machine
is shared). Ours is timed twice: walking the binary BVH (bvh2, the slow reference walk) and the 4-wide BVH
collapsed from it (bvh4, what `scene.intersect`, the renderer and the T&I model walk). The rays of real
renders (shadow, AO, reflection, refraction) are benchmarked in bench_render_rays.py.

    .venv/bin/python bench/bench_tracer.py [--repeats 5] [--res 512]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from sim_core.loaders import load_obj

import sim_core

MODELS = Path(__file__).resolve().parent.parent / "assets" / "models"


def bunny_grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    d = load_obj(MODELS / "stanford-bunny.obj")
    p = d.positions.astype(np.float64)
    t = d.triangles.astype(np.int64)
    size = p.max(axis=0) - p.min(axis=0)
    parts, tris = [], []
    for j in range(n):
        for i in range(n):
            parts.append(p + np.array([i * size[0] * 1.1, j * size[1] * 1.1, 0.0]))
            tris.append(t + len(p) * (j * n + i))
    return np.vstack(parts).astype(np.float32), np.vstack(tris)


def camera_rays(pos: np.ndarray, res: int) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    c = (lo + hi) / 2
    r = float(np.linalg.norm(hi - lo))
    cam = sim_core.Camera.look_at(c + np.array([0.3 * r, -0.9 * r, 0.5 * r]), c, (0, 0, 1), 0.75, res, res)
    return cam.primary_rays()


def diffuse_rays(scene, pos, tri, o, d, rng) -> tuple[np.ndarray, np.ndarray]:
    t, prim = scene.intersect(o, d)
    hit = prim >= 0
    p = o[hit].astype(np.float64) + d[hit].astype(np.float64) * t[hit, None]
    a, b, c = (pos[tri[prim[hit], k]].astype(np.float64) for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where((np.sum(n * d[hit], axis=1) > 0)[:, None], -n, n)
    # Cosine-weighted hemisphere around n.
    u1, u2 = rng.random(len(n)), rng.random(len(n))
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    helper = np.where((np.abs(n[:, 0]) > 0.9)[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    tx = np.cross(n, helper)
    tx /= np.linalg.norm(tx, axis=1, keepdims=True)
    ty = np.cross(n, tx)
    dirs = tx * (r * np.cos(phi))[:, None] + ty * (r * np.sin(phi))[:, None] + n * np.sqrt(1 - u1)[:, None]
    scale = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))
    origins = p + n * 1e-4 * scale
    return origins.astype(np.float32), dirs.astype(np.float32)


def run_time(fn, *args) -> float:
    # CPU time of this process: both tracers run on the calling thread only, and CPU time is far less
    # disturbed than wall time when other jobs share the machine.
    t0 = time.process_time()
    fn(*args)
    return time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--res", type=int, default=512)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    d = load_obj(MODELS / "stanford-bunny.obj")
    scenes = [
        ("bunny", d.positions.astype(np.float32), d.triangles.astype(np.int64)),
        ("bunny 3x3", *bunny_grid(3)),
    ]
    print(
        f"{'scene':<10} {'tris':>8} {'rays':<8} {'N':>7} {'bvh2 Mr/s':>10} {'bvh4 Mr/s':>10} "
        f"{'embree Mr/s':>12} {'bvh2/E':>7} {'bvh4/E':>7} {'agree':>8} {'build s':>8}"
    )
    for name, pos, tri in scenes:
        t0 = time.perf_counter()
        scene = sim_core.Scene.from_arrays(pos, tri)
        build = time.perf_counter() - t0
        es = rtcore_scene.EmbreeScene()
        TriangleMesh(es, pos, tri.astype(np.int32))
        o, dd = camera_rays(pos, args.res)
        es.run(o[:16], dd[:16])  # Embree commits its BVH lazily: build outside the timing
        sets = [("primary", o, dd), ("diffuse", *diffuse_rays(scene, pos, tri, o, dd, rng))]
        native = scene.native
        for kind, ro, rd in sets:
            two, four, emb = [], [], []
            for _ in range(args.repeats):  # interleave so all three see the same machine load
                two.append(run_time(native.intersect, ro, rd, 1, 2))
                four.append(run_time(native.intersect, ro, rd, 1, 4))
                emb.append(run_time(es.run, ro, rd))
            t2, t4, te = (float(np.median(x)) for x in (two, four, emb))
            _, prim = native.intersect(ro, rd, 1)
            ref = es.run(ro, rd, output=1)
            agree = float(np.mean((prim >= 0) == (ref["primID"] >= 0)))
            n = len(ro)
            print(
                f"{name:<10} {len(tri):>8} {kind:<8} {n:>7} {n / t2 / 1e6:>10.2f} {n / t4 / 1e6:>10.2f} "
                f"{n / te / 1e6:>12.2f} {te / t2:>7.2f} {te / t4:>7.2f} {agree:>8.5f} {build:>8.2f}"
            )


if __name__ == "__main__":
    main()
