"""Fidelity against Blender: the simulator at max quality against Cycles, on each blend_scenes scene.

Each scene's .blend is opened in the bpy module at its first frame. The simulator renders the add-on's
depsgraph translation at render level (``addon.translate.translate_for_render``: what the render engine
renders and the jobs optimise) with ``RenderSettings.max_quality()``. Cycles renders the same .blend as
the reference: CPU, Standard view transform, ``diffuse_bounces = 0`` (the simulated GPU traces no diffuse
inter-reflection), glossy and transmission bounces = the simulator's max depth, ``--samples`` samples
plus OpenImageDenoise. Both images go through the project's error pipeline (``service.evaluation.tone_map``:
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

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="bench-fidelity-"))

LUMA = np.array([0.2126, 0.7152, 0.0722])


def display(image: np.ndarray) -> np.ndarray:
    from service.evaluation import tone_map

    return tone_map(image)


def luminance(image: np.ndarray) -> float:
    """Mean Rec. 709 luma of the display image (what the artist sees)."""
    return float((display(image) @ LUMA).mean())


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
    """Cycles' linear render of the scene's own camera (EXR, read back; row 0 at the top)."""
    import bpy
    import OpenEXR

    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    r.use_compositing = False
    r.use_sequencer = False
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = samples
    cy.use_adaptive_sampling = False
    cy.use_denoising = True
    cy.denoiser = "OPENIMAGEDENOISE"
    cy.seed = 1
    cy.diffuse_bounces = 0
    cy.glossy_bounces = depth
    cy.transmission_bounces = depth
    cy.volume_bounces = 0
    cy.max_bounces = depth
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    path = Path(tempfile.mkdtemp(prefix="bench-fidelity-")) / "cycles.exr"
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.filepath = str(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    elapsed = time.perf_counter() - t0
    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        key = "RGBA" if "RGBA" in channels else "RGB"
        image = np.asarray(channels[key].pixels, dtype=np.float64)[..., :3]
    path.unlink()
    return image, elapsed


def save_pair(out: Path, name: str, simulated: np.ndarray, reference: np.ndarray) -> None:
    """simulator | Cycles, display-transformed, as one PNG."""
    from PIL import Image

    pair = np.concatenate([display(simulated), display(reference)], axis=1)
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
    from service.metrics import ssim

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
        lum_c, lum_s = luminance(reference), luminance(simulated)
        error = 1.0 - ssim(display(reference), display(simulated), data_range=1.0)
        print(f"| {name} | {stats['triangles']:,} | {lum_c:.3f} | {lum_s:.3f} | {lum_s / lum_c:.3f} | "
              f"{error:.3f} | {cycles_s:.1f} | {sim_s:.1f} |", flush=True)
        remarks[name] = [n for n in notes if n.severity == "warning"]
        if args.out is not None:
            save_pair(args.out, name, simulated, reference)
    for name, warnings in remarks.items():
        for note in warnings:
            print(f"  {name}: {note}")


if __name__ == "__main__":
    main()
