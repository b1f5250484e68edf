"""Fidelity against Blender: the simulator at max quality against Cycles, on each blend_scenes scene.

Each scene's .blend is opened in the bpy module at its first frame. The simulator renders the add-on's
depsgraph translation at render level (``addon.translate.translate_for_render``: what the render engine
renders and the jobs optimise) with ``RenderSettings.max_quality()``. Cycles renders the same .blend as
the reference: CPU, Standard view transform, ``diffuse_bounces = 0`` (the simulated GPU traces no diffuse
inter-reflection), glossy and transmission bounces = the simulator's max depth, ``--samples`` samples
plus OpenImageDenoise. Both images go through the project's error pipeline (``sim_core.image.linear_to_srgb``:
clamp and sRGB, then ``service.metrics.ssim``). Prints per scene: mean display luminance (Rec. 709 luma
of the display image) of both, their ratio (simulator / Cycles), 1-SSIM, the render times and the
translation's warnings. Target: ratio within 10 % and 1-SSIM <= 0.10.

    .venv/bin/python bench/bench_fidelity.py [--scene NAME ...] [--width 320 --height 180]
        [--samples 128] [--out DIR (side-by-side PNGs)] [--scenes DIR]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image
from sim_core.image import linear_to_srgb

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="bench-fidelity-"))

sys.path.insert(0, str(ROOT / "tests"))
import cycles_reference  # noqa: E402  (the Cycles reference set-up and the fidelity metrics, shared with tests)


def open_scene(blend: Path):
    import bpy

    bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
    scene = bpy.context.scene
    scene.frame_set(scene.frame_start)
    return scene


def simulate(scene, width: int, height: int) -> tuple[np.ndarray, float, list, dict]:
    import sim_core
    from addon.translate import translate_for_render

    t0 = time.perf_counter()
    translation = translate_for_render(scene)
    data = translation.scene_data
    sim_scene = sim_core.Scene.from_scene_data(data)
    cam = data.cameras[0]
    camera = sim_core.Camera.from_blender(cam.matrix_world, cam.vfov, width, height)
    result = sim_core.render(sim_scene, camera, sim_core.RenderSettings.max_quality())
    return np.asarray(result.image, dtype=np.float64), time.perf_counter() - t0, translation.notes, \
        translation.stats


def cycles(scene, width: int, height: int, samples: int, depth: int) -> tuple[np.ndarray, float]:
    """Cycles' linear render of the scene's own camera (denoised; row 0 at the top) and its time."""
    cycles_reference.cycles_settings(scene, width, height, samples, depth=depth, denoise=True)
    t0 = time.perf_counter()
    image = cycles_reference.cycles_render(scene)
    return image, time.perf_counter() - t0


def save_pair(out: Path, name: str, simulated: np.ndarray, reference: np.ndarray) -> None:
    """simulator | Cycles, display-transformed, as one PNG."""
    pair = np.concatenate([linear_to_srgb(simulated), linear_to_srgb(reference)], axis=1)
    out.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.round(pair * 255).astype(np.uint8)).save(out / f"{name}.png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    from blend_scenes.scenes import SCENES

    ap.add_argument("--scene", action="append", choices=SCENES, help="scene (repeatable); default: all")
    ap.add_argument("--scenes", type=Path, default=ROOT / "blend_scenes" / "build")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--samples", type=int, default=128, help="Cycles samples per pixel (denoised)")
    ap.add_argument("--out", type=Path, default=None, help="write simulator | Cycles PNGs here")
    args = ap.parse_args()
    names = args.scene or list(SCENES)

    import sim_core
    from blend_scenes.build import build

    build(names, args.scenes)
    depth = sim_core.RenderSettings.max_quality().max_depth
    print(f"\n{args.width}x{args.height}, each scene's camera at its first frame; simulator max quality "
          f"(depth {depth}) on the depsgraph translation; Cycles {args.samples} spp + OIDN, diffuse bounces "
          f"0, glossy/transmission {depth}, Standard view transform")
    print("| scene | triangles | Cycles luminance | simulator luminance | ratio | 1-SSIM | Cycles s | "
          "simulator s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    remarks: dict[str, list] = {}
    for name in names:
        scene = open_scene(args.scenes / name / "scene.blend")
        simulated, sim_s, notes, stats = simulate(scene, args.width, args.height)
        reference, cycles_s = cycles(scene, args.width, args.height, args.samples, depth)
        lum_c, lum_s = (cycles_reference.display_luminance(x) for x in (reference, simulated))
        ratio, error = cycles_reference.fidelity(reference, simulated)
        print(f"| {name} | {stats['triangles']:,} | {lum_c:.3f} | {lum_s:.3f} | {ratio:.3f} | "
              f"{error:.3f} | {cycles_s:.1f} | {sim_s:.1f} |", flush=True)
        remarks[name] = [n for n in notes if n.severity == "warning"]
        if args.out is not None:
            save_pair(args.out, name, simulated, reference)
    for name, warnings in remarks.items():
        for note in warnings:
            print(f"  {name}: {note}")


if __name__ == "__main__":
    main()
