"""The tile estimator against whole frames: how far its error and power are from the exact figures at
display resolution, and what it costs (``service.display_pricing``).

For each scene, evenly spread path frames at the given display size, random settings of the default
space plus the maximum-quality one: every setting priced exactly (whole frames: reference and setting
at display resolution) and by each estimator configuration (share of blocks traced, auxiliary
divisor). Prints |estimated - exact| error (all settings, and those with exact error <= 0.05, where
the budgets live), relative power difference, how the estimator's own standard error compares
(|difference| / standard error), and CPU time against the exact pricing.

    .venv/bin/python bench/bench_display_pricing.py teapot chess --size 640x360 --cameras 4 --settings 8

``--dump FILE`` writes every estimator evaluation's figures (error, power, frame time, breakdown) as
JSON, so that two builds' figures can be compared to the last digit.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from addon.core.campaign import parse_size
from service.camera_path import CameraPath
from service.display_pricing import DisplayPricing, price_camera
from service.evaluation import CameraSpec, read_scene
from service.params import default_space

REPO = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--size", type=parse_size, default=(640, 360))
    ap.add_argument("--cameras", type=int, default=4)
    ap.add_argument("--settings", type=int, default=8)
    ap.add_argument("--fraction", type=float, nargs="+", default=[0.1, 0.2])
    ap.add_argument("--aux", type=int, nargs="+", default=[4])
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--dump", type=Path, default=None, help="write the estimator's figures here (JSON)")
    args = ap.parse_args()
    space = default_space()
    counts = [len(p.values) for p in space.parameters]
    configs = [DisplayPricing("tiles", f, None, a, args.seed) for a in args.aux for f in args.fraction]
    print(f"display {args.size[0]}x{args.size[1]}, {args.cameras} cameras x ({args.settings} random settings "
          "+ max quality) per scene")
    print("| scene | estimator | |de| median | |de| p95 | |de| max | |de| p95 (e <= 0.05) | |dP|/P median | "
          "|dP|/P p95 | |dP|/P max | |de| <= 2 se | CPU vs whole frames |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    dump: dict[str, list] = {}
    for name in args.scenes:
        d = REPO / "blend_scenes" / "build" / name
        scene = read_scene(d / "scene.rbscene")
        path = CameraPath.load(d / "path.json")
        rng = np.random.default_rng(args.seed)
        exact: list[tuple[float, float]] = []
        est: dict[int, list[tuple[float, float, float]]] = {i: [] for i in range(len(configs))}
        cpu_exact, cpu_est = 0.0, [0.0] * len(configs)
        for k in range(args.cameras):
            f = path.frames[round((k + 0.5) * (len(path) - 1) / args.cameras)]
            m = np.asarray(f.matrix_world, dtype=np.float64)
            cam = CameraSpec.from_matrix(m, f.vfov, *args.size)
            sets = [space.max_quality_indices()] + [tuple(int(v) for v in rng.integers(0, counts))
                                                    for _ in range(args.settings)]
            t = time.process_time()
            full = price_camera(scene, cam, sets, space, profile="mobile", fps=30.0, metric="ssim",
                                pricing=DisplayPricing("full"), threads=args.threads)
            cpu_exact += time.process_time() - t
            exact += [(e.error, e.power_w) for e in full]
            for i, cfg in enumerate(configs):
                t = time.process_time()
                res = price_camera(scene, cam, sets, space, profile="mobile", fps=30.0, metric="ssim",
                                   pricing=cfg, threads=args.threads)
                cpu_est[i] += time.process_time() - t
                est[i] += [(e.error, e.power_w, e.breakdown.get("display.se_error", 0.0)) for e in res]
                dump.setdefault(f"{name} camera {k} f={cfg.fraction:g} aux {cfg.aux_divisor}", []).extend(
                    [e.error, e.power_w, e.frame_time_s, sorted(e.breakdown.items())] for e in res)
        ex = np.asarray(exact)
        for i, cfg in enumerate(configs):
            es = np.asarray(est[i])
            de = np.abs(es[:, 0] - ex[:, 0])
            dp = np.abs(es[:, 1] / ex[:, 1] - 1.0)
            low = ex[:, 0] <= 0.05
            covered = np.mean(de <= 2 * es[:, 2] + 1e-12)
            print(f"| {name} | f={cfg.fraction:g}, aux 1/{cfg.aux_divisor} | {np.median(de):.4f} | "
                  f"{np.quantile(de, 0.95):.4f} | {de.max():.4f} | "
                  f"{np.quantile(de[low], 0.95) if low.any() else float('nan'):.4f} | {np.median(dp):.3f} | "
                  f"{np.quantile(dp, 0.95):.3f} | {dp.max():.3f} | {covered:.0%} | "
                  f"{cpu_est[i] / cpu_exact:.2f} |", flush=True)
    if args.dump is not None:
        args.dump.write_text(json.dumps(dump, indent=1))


if __name__ == "__main__":
    main()
