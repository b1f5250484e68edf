"""Where the tile estimator's traced pixels go: the sampled blocks, their SSIM margins, the whole tiles
that hold them, and the planned windows with their aprons (``service.display_pricing.windows``), as a
share of the frame: the previous planning (every tile holding a needed pixel traced whole, on the tile
grid) and the current one (the sampled tiles whole, the margins' tiles cut to the pixels the SSIM reads).

For each scene, evenly spread path frames at the display size, the estimator's sample at each share, at
the maximum-quality setting (the reference every camera traces). With ``--rays`` both plans' windows
are also rendered: every ray they trace (counted and apron, ``render_window(...).extra["apron_rays"]``),
the current plan's against the previous one's.

    .venv/bin/python bench/bench_window_area.py teapot chess --size 640x360 --cameras 2 --rays
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import sim_core
from addon.core.campaign import parse_size
from service.camera_path import CameraPath
from service.display_pricing import DisplayPricing
from service.display_pricing.design import build_design, display_cameras
from service.display_pricing.tracing import Renderer, needed_tiles
from service.display_pricing.windows import apron_pixels, plan_windows, traced_area
from service.evaluation import CameraSpec, read_scene
from service.params import default_space

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--size", type=parse_size, default=(640, 360))
    ap.add_argument("--cameras", type=int, default=2)
    ap.add_argument("--fraction", type=float, nargs="+", default=[0.1, 0.25])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rays", action="store_true", help="render the planned windows: apron rays")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    space = default_space()
    print(f"display {args.size[0]}x{args.size[1]}, maximum quality, shares of the frame's pixels")
    print("| scene | camera | share | block / tile / apron px | sampled blocks | + SSIM margins | "
          "whole tiles | traced, whole tiles (before) | traced, margins cut (after) | "
          "windows before / after | rays after / before |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        d0 = REPO / "blend_scenes" / "build" / name
        scene = read_scene(d0 / "scene.rbscene")
        path = CameraPath.load(d0 / "path.json")
        renderer = Renderer(scene, args.threads)
        s = space.to_settings(space.max_quality_indices())
        for k in range(args.cameras):
            f = path.frames[round((k + 0.5) * (len(path) - 1) / args.cameras)]
            m = np.asarray(f.matrix_world, dtype=np.float64)
            cam = CameraSpec(tuple(m[:3, 3]), tuple(-m[:3, 2]), tuple(m[:3, 1]), f.vfov, *args.size)
            for share in args.fraction:
                pricing = DisplayPricing("tiles", share, None, 4, args.seed)
                d, _ = build_design(renderer, cam, space, pricing, "ssim")
                full_cam, _ = display_cameras(cam, pricing)
                w, h = sim_core.render_size(full_cam, s)
                ts = s.tile_size
                blocks = d.sampled.tolist()
                need, _owner, counted, tiles = needed_tiles(d, blocks, w, h, ts)
                sampled = np.zeros((h, w), dtype=bool)
                sx, sy = w / d.W, h / d.H
                for b in blocks:
                    bx, by = b % d.nbx, b // d.nbx
                    sampled[round(by * d.B * sy):round((by + 1) * d.B * sy),
                            round(bx * d.B * sx):round((bx + 1) * d.B * sx)] = True
                ys, xs = np.nonzero(tiles)
                tile_px = int(np.sum(np.minimum(ts, w - xs * ts) * np.minimum(ts, h - ys * ts)))
                a = apron_pixels(s)
                before = plan_windows(tiles, w, h, ts, a)
                after = plan_windows(counted, w, h, ts, a, need)
                frame = w * h
                rays = "-"
                if args.rays:
                    total = []
                    for windows in (before, after):
                        n = 0
                        for win in windows:
                            r = sim_core.render_window(scene, full_cam, s, win, threads=args.threads)
                            n += r.counters["rays_total"] + r.extra["apron_rays"]
                        total.append(n)
                    rays = f"{total[1] / total[0]:.2f}" if total[0] else "-"
                print(f"| {name} | {k} | {share:g} | {d.B} / {ts} / {a} | {sampled.sum() / frame:.2f} | "
                      f"{need.sum() / frame:.2f} | {tile_px / frame:.2f} | "
                      f"{traced_area(before, w, h, a) / frame:.2f} | "
                      f"{traced_area(after, w, h, a) / frame:.2f} | "
                      f"{len(before)} / {len(after)} | {rays} |", flush=True)


if __name__ == "__main__":
    main()
