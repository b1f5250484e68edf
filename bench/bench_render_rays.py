"""The rays of real renders, traced by our renderer and by Embree: rays/s per thread at max quality.

For each scene (blend_scenes, built first if missing; first frame of its camera path) the renderer renders
the max-quality preset on one thread with its ray log on: every primary, shadow, AO, reflection,
refraction and glossy ray it traced, with its interval. Then, interleaved over the repeats so all of them
see the same machine load (process CPU time, median):
- "render": our full render (ray generation, traversal, shading, sampling, counters and cache model),
  rays_total / time: the per-thread speed the store's pricing at display resolution depends on;
- "bvh4" / "bvh2": our traversal alone on the logged rays (closest hit for primary/reflection/refraction/
  glossy, any-hit occlusion for shadow/AO) over the 4-wide BVH the renderer walks and over the binary
  reference walk;
- "embree": Embree (embreex, rtcIntersect1 / rtcOccluded1 per ray) on the same rays and intervals.
"agree" is the share of rays whose hit/miss (or occluded) answer equals Embree's.

    .venv/bin/python bench/bench_render_rays.py [--scenes teapot chess] [--width 320 --height 180]
        [--repeats 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sim_core.loaders import load_gltf  # noqa: E402
from sim_core.render import ANY_HIT_KINDS, RAY_KINDS  # noqa: E402

import sim_core  # noqa: E402
from blend_scenes.build import DEFAULT_OUT, build  # noqa: E402
from service.camera_path import CameraPath  # noqa: E402

EMBREE_INF = np.float32(1e37)  # Embree's "unbounded" tfar


def trace_ours(native, width: int, any_hit: bool, o, d, tm):
    """Our traversal alone: any-hit occlusion or closest hit over the tree of the given width."""
    return (native.occluded if any_hit else native.intersect)(o, d, 1, width, tm)


def trace_embree(es, any_hit: bool, o, d, etm):
    return es.run(o, d, dists=etm, query="OCCLUDED" if any_hit else "INTERSECT")


def cpu_time(fn, *args, **kwargs) -> float:
    t0 = time.process_time()
    fn(*args, **kwargs)
    return time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["teapot", "chess"])
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="built blend_scenes folder")
    args = ap.parse_args()
    build(args.scenes, args.out)
    settings = sim_core.RenderSettings.max_quality()
    print(f"\nmax quality, {args.width}x{args.height}, one thread, median of {args.repeats} "
          "(process CPU time)")
    print(f"{'scene':<8} {'rays':<11} {'N':>9} {'render Mr/s':>11} {'bvh4 Mr/s':>10} {'bvh2 Mr/s':>10} "
          f"{'embree Mr/s':>11} {'bvh4/E':>7} {'render/E':>8} {'agree':>8}")
    for name in args.scenes:
        data = load_gltf(args.out / name / "scene.glb")
        scene = sim_core.Scene.from_scene_data(data)
        frame = CameraPath.load(args.out / name / "path.json").frames[0]
        cam = sim_core.Camera.from_blender(frame.matrix_world, frame.vfov, args.width, args.height)
        logged = sim_core.render(scene, cam, settings, threads=1, log_rays=True)
        rays = logged.rays
        total = int(logged.counters["rays_total"])
        es = rtcore_scene.EmbreeScene()
        TriangleMesh(es, data.positions.astype(np.float32), data.triangles.astype(np.int32))
        native = scene.native
        groups = []
        for kind in RAY_KINDS:
            m = rays.of_kind(kind)
            if m.any():
                o, d, tm = rays.origins[m], rays.directions[m], rays.tmax[m]
                groups.append((kind, kind in ANY_HIT_KINDS, o, d, tm, np.where(np.isinf(tm), EMBREE_INF, tm)))
        es.run(groups[0][2][:16], groups[0][3][:16])  # Embree builds its BVH lazily: outside the timing

        times: dict[str, list[float]] = {}
        for _ in range(args.repeats):
            times.setdefault("render", []).append(cpu_time(sim_core.render, scene, cam, settings, threads=1))
            for kind, any_hit, o, d, tm, etm in groups:
                for width in (4, 2):
                    t = cpu_time(trace_ours, native, width, any_hit, o, d, tm)
                    times.setdefault(f"{kind}/bvh{width}", []).append(t)
                times.setdefault(f"{kind}/embree", []).append(cpu_time(trace_embree, es, any_hit, o, d, etm))
        med = {k: float(np.median(v)) for k, v in times.items()}
        render_rate = total / med["render"] / 1e6
        sums = {"bvh4": 0.0, "bvh2": 0.0, "embree": 0.0}
        agree_total = 0
        for kind, any_hit, o, d, tm, etm in groups:
            n = len(o)
            ref = trace_embree(es, any_hit, o, d, etm) >= 0
            got = trace_ours(native, 4, any_hit, o, d, tm)
            hit = got if any_hit else got[1] >= 0
            agree = int(np.sum(hit == ref))
            agree_total += agree
            t4, t2, te = med[f"{kind}/bvh4"], med[f"{kind}/bvh2"], med[f"{kind}/embree"]
            for k, t in (("bvh4", t4), ("bvh2", t2), ("embree", te)):
                sums[k] += t
            print(f"{name:<8} {kind:<11} {n:>9,} {'':>11} {n / t4 / 1e6:>10.2f} {n / t2 / 1e6:>10.2f} "
                  f"{n / te / 1e6:>11.2f} {te / t4:>7.2f} {'':>8} {agree / n:>8.5f}")
        print(f"{name:<8} {'all':<11} {total:>9,} {render_rate:>11.2f} {total / sums['bvh4'] / 1e6:>10.2f} "
              f"{total / sums['bvh2'] / 1e6:>10.2f} {total / sums['embree'] / 1e6:>11.2f} "
              f"{sums['embree'] / sums['bvh4']:>7.2f} {sums['embree'] / med['render']:>8.2f} "
              f"{agree_total / total:>8.5f}")


if __name__ == "__main__":
    main()
