"""Which of the paper's presets are real time on a hardware profile, and why (the profile's reasoning).

For a few evenly spaced frames of a scene's camera path this renders the four fixed presets (Max,
Max-Mid, Mid-Min, Min, as the main job builds them) at a stated size, prices each render on the profile
and scales dynamic energy and frame time by the pixel ratio to the path's resolution (as the store and
the main job do), and prints per preset the ranges over the frames of:

- the frame rate the modelled GPU reaches at the path's resolution when asked for the path's frame rate,
  and the rate it could reach flat out (1 / frame time),
- rays per frame and 4-wide node steps per ray at the path's resolution,
- the ray rate the profile's T&I units sustain on these rays (rays / T&I busy time) and the ray rate
  real time would need (rays per frame x fps),
- the dynamic power real time would need (E_dynamic x fps), the power drawn at the frame rate reached
  (sim_core.sustained_power) and the full-speed power P_static + E_dynamic / frame time.

    .venv/bin/python bench/bench_real_time.py [--scene teapot] [--frames 5] [--size 640x360]
        [--path-size WxH] [--profile mobile]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import sim_core
from addon.core.report import PRESET_LEVELS, preset_indices
from blend_scenes.build import DEFAULT_OUT, build
from service.camera_path import CameraPath
from service.evaluation import CameraSpec, load_scene
from service.params import default_space

NAMES = {"max": "Max", "max_mid": "Max-Mid", "mid_min": "Mid-Min", "min": "Min"}


def span(values: list[float], fmt: str) -> str:
    lo, hi = min(values), max(values)
    return format(lo, fmt) if format(lo, fmt) == format(hi, fmt) else f"{format(lo, fmt)}-{format(hi, fmt)}"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="teapot")
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--size", default="640x360", help="render size WxH (priced for the path's resolution)")
    ap.add_argument("--path-size", default=None,
                    help="price for this display size WxH instead of the path's own resolution")
    ap.add_argument("--profile", default="mobile")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))

    build([args.scene])
    scene_dir = Path(DEFAULT_OUT) / args.scene
    path = CameraPath.load(scene_dir / "path.json")
    scene = load_scene(scene_dir / "scene.glb").get()
    prof = sim_core.load_profile(args.profile)
    path_w, path_h = (path.frames[0].resolution if args.path_size is None
                      else (int(v) for v in args.path_size.lower().split("x")))
    ratio = (path_w * path_h) / (width * height)
    space = default_space()
    counts = [len(p.values) for p in space.parameters]
    mq = list(space.max_quality_indices())
    picks = np.linspace(0, len(path) - 1, args.frames).round().astype(int)
    print(f"{args.scene}: frames {list(picks)} of {len(path)}, rendered at {width}x{height}, priced for "
          f"{path_w}x{path_h} (x{ratio:g}) at {path.fps:g} fps on `{prof.name}` (P_static "
          f"{prof.static_power_w:g} W)")
    print(f"{'preset':>8} {'fps reached':>12} {'max fps':>10} {'M rays/frame':>13} {'steps/ray':>10} "
          f"{'T&I G rays/s':>13} "
          f"{'needs G rays/s':>15} {'E*fps (W)':>10} {'power (W)':>10} {'full speed (W)':>15} "
          f"{'CPU s':>6}")
    for mode, level in PRESET_LEVELS.items():
        settings = space.to_settings(tuple(preset_indices(counts, mq, level)))
        rows: dict[str, list[float]] = {
            k: [] for k in ("fps", "max", "rays", "steps", "ti", "need", "dyn", "p", "full")}
        cpu = time.process_time()
        for i in picks:
            f = path.frames[int(i)]
            m = np.asarray(f.matrix_world, dtype=np.float64)
            camera = CameraSpec.from_matrix(m, f.vfov, width, height)
            result = sim_core.render(scene, camera.to_camera(), settings, threads=args.threads)
            rep = sim_core.price(result, prof, path.fps)
            energy = rep.dynamic_energy_j * ratio
            frame_time = rep.frame_time_s * ratio
            power, reached = sim_core.sustained_power(prof.static_power_w, energy, frame_time, path.fps)
            rays = rep.rays_total * ratio
            rows["fps"].append(reached)
            rows["max"].append(1.0 / frame_time)
            rows["rays"].append(rays / 1e6)
            rows["steps"].append(result.counters["bvh_node_visits"] / max(1, rep.rays_total))
            rows["ti"].append(rays / (rep.unit_time_s["ti"] * ratio) / 1e9)
            rows["need"].append(rays * path.fps / 1e9)
            rows["dyn"].append(energy * path.fps)
            rows["p"].append(power)
            rows["full"].append(prof.static_power_w + energy / frame_time)
        cpu = time.process_time() - cpu
        print(f"{NAMES[mode]:>8} {span(rows['fps'], '.3g'):>12} {span(rows['max'], '.3g'):>10} "
              f"{span(rows['rays'], '.3g'):>13} {span(rows['steps'], '.2g'):>10} "
              f"{span(rows['ti'], '.2f'):>13} {span(rows['need'], '.2g'):>15} "
              f"{span(rows['dyn'], '.2g'):>10} {span(rows['p'], '.2f'):>10} {span(rows['full'], '.2f'):>15} "
              f"{cpu:6.1f}")


if __name__ == "__main__":
    main()
