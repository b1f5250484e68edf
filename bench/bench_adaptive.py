"""Adaptive ray sampling on the modelled mobile RT GPU: the adaptive-sampling seed's Figure 7 and Table 1.

For each test scene (blend_scenes, built on demand into --scenes) and a few frames of its camera path, four
renders per frame with otherwise identical settings: FSAA 2x2 and adaptive supersampling 2x2 (compared),
1 spp and adaptive undersampling 2x2 (compared), and the seed's multi-rate extension (per-tile 2x2 or 4x4
from the previous frame's similarity ratio; the previous frame is the same view rendered once).
Each render is priced on the mobile profile. Reported,
relative to the reference of its pair (as seed Fig. 7):
  perf   = frame rate at full speed (1 / frame time, frame time = slowest unit),
  power  = P_static + E_frame / frame_time (running flat out, as the seed measured),
  perf/W = frames per joule,
for the whole GPU and for the T&I unit alone (the seed's Fig. 7 is "for the execution of the T&I unit":
perf = 1 / T&I busy time, power = T&I energy / T&I time). PSNR of each adaptive image against its
reference image (seed Table 1), on display values (linear -> sRGB, clipped to [0, 1]).

Run: .venv/bin/python bench/bench_adaptive.py [--width 640] [--frames 3] [--scenes DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from sim_core.image import linear_to_srgb

from sim_core import Camera, RenderSettings, Scene, load_profile, price, render

SCENES = ("teapot", "chess", "lab", "hall", "valley")
LOW_FREQUENCY = {"teapot", "hall"}  # large smooth surfaces (the seed's Teapot/BMW class)
DEFAULT_SCENES = Path(__file__).resolve().parent.parent / "blend_scenes" / "build"


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((linear_to_srgb(a) - linear_to_srgb(b)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(1.0 / mse)


def ensure_scenes(out: Path, names: tuple[str, ...]) -> None:
    missing = [n for n in names if not (out / n / "stats.json").exists()]
    if missing:
        from blend_scenes.build import build

        build(missing, out)


def cameras(path_json: Path, width: int, frames: int) -> list[Camera]:
    d = json.loads(path_json.read_text())
    fr = d["frames"]
    picks = [fr[int(i)] for i in np.linspace(0, len(fr) - 1, frames + 2)[1:-1]] if frames > 1 else [fr[0]]
    out = []
    for f in picks:
        w0, h0 = f["resolution"]
        h = max(8, round(width * h0 / w0))
        out.append(Camera.from_blender(np.array(f["matrix_world"]), f["vfov"], width, h))
    return out


def ti(rep) -> tuple[float, float]:
    """(T&I busy time, T&I dynamic energy)."""
    e = sum(rep.energy_j[b] for b in ("traversal", "intersection", "comparator", "cache"))
    return rep.unit_time_s["ti"], e


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--scenes", type=Path, default=DEFAULT_SCENES)
    ap.add_argument("--threshold", type=float, default=20.0, help="similarity normal threshold (degrees)")
    args = ap.parse_args()
    ensure_scenes(args.scenes, SCENES)
    prof = load_profile("mobile")
    base = RenderSettings(normal_threshold_deg=args.threshold)
    pairs = (("adaptive supersampling 2x2 vs FSAA 2x2", base.replace(mode="fsaa", block=2),
              base.replace(mode="supersample", block=2)),
             ("adaptive undersampling 2x2 vs 1 spp", base.replace(mode="1spp"),
              base.replace(mode="undersample", block=2)),
             ("multi-rate undersampling (2x2/4x4 per tile) vs 1 spp", base.replace(mode="1spp"),
              base.replace(mode="undersample", block=2, multirate=True)))
    print(f"## Adaptive sampling on the mobile profile, {args.width} px wide, {args.frames} frames per "
          f"scene, normal threshold {args.threshold} deg")
    print("| scene | comparison | rays traced | GPU perf | GPU power | GPU perf/W | T&I perf | T&I power | "
          "T&I perf/W | SRP overhead (sim.+interp.) | PSNR dB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    summary: dict[str, list[float]] = {}
    t_start = time.perf_counter()
    for name in SCENES:
        scene = Scene.from_gltf(args.scenes / name / "scene.glb")
        cams = cameras(args.scenes / name / "path.json", args.width, args.frames)
        for label, ref_s, ada_s in pairs:
            acc = {k: [] for k in ("rays", "perf", "power", "ppw", "tperf", "tpower", "tppw", "ovh", "psnr")}
            for cam in cams:
                r_ref = render(scene, cam, ref_s, cache=prof.cache)
                prev = None
                if ada_s.multirate:  # the per-tile rates come from the previous frame's similarity ratios
                    prev = render(scene, cam, ada_s, cache=prof.cache)
                r_ada = render(scene, cam, ada_s, cache=prof.cache, previous=prev)
                p_ref, p_ada = price(r_ref, prof, 30, scene=scene), price(r_ada, prof, 30, scene=scene)
                acc["rays"].append(r_ada.counters["rays_total"] / r_ref.counters["rays_total"])
                acc["perf"].append(p_ada.max_fps / p_ref.max_fps)
                acc["power"].append(p_ada.power_full_speed_w / p_ref.power_full_speed_w)
                acc["ppw"].append(p_ada.perf_per_watt / p_ref.perf_per_watt)
                (t_r, e_r), (t_a, e_a) = ti(p_ref), ti(p_ada)
                acc["tperf"].append(t_r / t_a)
                acc["tpower"].append((e_a / t_a) / (e_r / t_r))
                acc["tppw"].append(e_r / e_a)
                srp = sum(p_ada.cycles[b] for b in ("raygen", "shading", "similarity", "interpolation",
                                                    "reprojection", "env_filter"))
                acc["ovh"].append((p_ada.cycles["similarity"] + p_ada.cycles["interpolation"]) / srp)
                acc["psnr"].append(psnr(r_ref.image, r_ada.image))
            m = {k: float(np.mean(v)) for k, v in acc.items()}
            summary.setdefault(label + " GPU", []).append(m["ppw"])
            summary.setdefault(label + " T&I", []).append(m["tppw"])
            summary.setdefault(label + " PSNR", []).append(m["psnr"])
            print(f"| {name} | {label} | {m['rays']:.2f} | {m['perf']:.2f}x | {m['power']:.2f}x | "
                  f"{m['ppw']:.2f}x | {m['tperf']:.2f}x | {m['tpower']:.2f}x | {m['tppw']:.2f}x | "
                  f"{100 * m['ovh']:.1f} % | {m['psnr']:.1f} |")
    print()
    for k, v in summary.items():
        print(f"- {k}: min {min(v):.2f}, mean {np.mean(v):.2f}, max {max(v):.2f}")
    print(f"\n(total bench time {time.perf_counter() - t_start:.0f} s)")


if __name__ == "__main__":
    main()
