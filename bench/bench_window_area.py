"""Where the tile estimator's traced pixels go: the sampled blocks, their SSIM margins, the whole tiles
that hold them, and the planned windows with their aprons (``service.display_pricing.windows``), as a
share of the frame: the previous planning (every tile holding a needed pixel traced whole, on the tile
grid) and the current one (the sampled tiles whole, the margins' tiles cut to the pixels the SSIM reads).

For each scene, evenly spread path frames at the display size, the estimator's sample at each share, at
the maximum-quality setting (the reference every camera traces). With ``--rays`` both plans' windows
are also rendered: every ray they trace (counted and apron, ``render_window(...).extra["apron_rays"]``),
the current plan's against the previous one's. With ``--cpu N`` the windows of the maximum-quality
setting and N random settings per camera are timed under both plans, next to the whole frame.

    .venv/bin/python bench/bench_window_area.py teapot chess --size 640x360 --cameras 2 --rays
"""

from __future__ import annotations

import argparse
import time
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
    ap.add_argument("--cpu", type=int, default=None, metavar="N",
                    help="also time both plans' windows and the whole frame (CPU) at maximum quality and N "
                         "random settings per camera (bench_display_pricing's draw)")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    space = default_space()
    counts = [len(p.values) for p in space.parameters]
    cpu_rows: list[str] = []
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
        rng = np.random.default_rng(args.seed)
        for k in range(args.cameras):
            f = path.frames[round((k + 0.5) * (len(path) - 1) / args.cameras)]
            m = np.asarray(f.matrix_world, dtype=np.float64)
            cam = CameraSpec.from_matrix(m, f.vfov, *args.size)
            timed = [space.max_quality_indices()] + [tuple(int(v) for v in rng.integers(0, counts))
                                                     for _ in range(args.cpu or 0)]
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
                if args.cpu is not None:
                    cpu_rows += _cpu_rows(renderer, full_cam, space, timed, d, f"{name} | {k} | {share:g}")
    if cpu_rows:
        print("\nCPU of the windows of each setting (s): every needed tile whole (before), margins cut "
              "(after), and the whole frame")
        print("| scene | camera | share | setting | apron px | before | after | whole frame |")
        print("|---|---|---|---|---|---|---|---|")
        print("\n".join(cpu_rows))


def _cpu_rows(renderer: Renderer, full_cam, space, settings, d, label: str) -> list[str]:
    """One row per setting: CPU of its windows planned with whole tiles and with the margins cut, and of
    its whole frame."""
    rows = []
    blocks = d.sampled.tolist()
    for idx in settings:
        s = space.to_settings(idx)
        cpu = []
        for plan in (_whole_tiles, plan_windows):
            t = time.process_time()
            renderer.windows(full_cam, s, blocks, d, plan=plan)
            cpu.append(time.process_time() - t)
        t = time.process_time()
        renderer.frame(full_cam, s)
        cpu.append(time.process_time() - t)
        name = f"{s.mode} {s.block}, scale {s.resolution_scale:g}, AO {s.ao_samples}"
        rows.append(f"| {label} | {name} | {apron_pixels(s)} | {cpu[0]:.2f} | {cpu[1]:.2f} | {cpu[2]:.2f} |")
    return rows


def _whole_tiles(mask: np.ndarray, w: int, h: int, ts: int, apron: int, reads: np.ndarray) -> list:
    """The previous planning: every tile holding a needed pixel traced whole, on the tile grid."""
    held = np.add.reduceat(np.add.reduceat(reads.astype(np.int32), np.arange(0, h, ts), axis=0),
                           np.arange(0, w, ts), axis=1) > 0
    return plan_windows(mask | held, w, h, ts, apron)


if __name__ == "__main__":
    main()
