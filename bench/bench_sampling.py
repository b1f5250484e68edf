"""Sampling modes against their references on three scenes built from the bundled models (seed Table 1).

Undersampling and multi-rate are compared with 1 spp, adaptive supersampling with FSAA of the same grid,
stereo (right eye by reprojection) with a directly traced right eye. Columns: rays traced relative to the
reference (all ray kinds), samples traced relative to the reference, wall time (2 threads), PSNR and
1-SSIM of the clipped linear image against the reference. Two shading configurations: "hard" (hard
shadows, no AO: deterministic shading) and "soft" (4 soft-shadow and 4 AO samples per hit: the 1 spp
reference carries per-pixel Monte Carlo noise that interpolation smooths away, which PSNR counts as error).

    .venv/bin/python bench/bench_sampling.py [--width 320 --height 180]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from sim_core.loaders import load_obj
from skimage.metrics import structural_similarity

import sim_core
from sim_core import Camera, Light, Material, RenderSettings, Scene, render, render_stereo

# The scenes are shared with the tests (tests/tracer_scenes.py).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from tracer_scenes import (
    effects_camera,
    effects_scene,
    teapot_camera,
    teapot_on_plane,
    with_ground,
)

MODELS = Path(__file__).resolve().parent.parent / "assets" / "models"


def cow_and_spot() -> Scene:
    """Two diffuse models on a plane under two soft lights (shadow boundaries, contact shadows)."""
    parts, tris, ids = [], [], []
    off = 0
    for k, (name, x) in enumerate((("cow.obj", -1.1), ("spot.obj", 1.1))):
        d = load_obj(MODELS / name)
        p = d.positions.astype(np.float64)
        lo, hi = p.min(axis=0), p.max(axis=0)
        p = (p - (lo + hi) / 2) * (1.8 / float(np.max(hi - lo)))
        p[:, 2] -= p[:, 2].min()
        p[:, 0] += x
        parts.append(p)
        tris.append(d.triangles.astype(np.int64) + off)
        ids.append(np.full(len(d.triangles), k + 1))
        off += len(p)
    p, t, ground = with_ground(np.vstack(parts), np.vstack(tris), size=6.0)
    oid = np.r_[np.concatenate(ids), np.zeros(ground.sum(), np.int64)]
    mats = [
        Material(base_color=(0.75, 0.75, 0.7), roughness=0.9),
        Material(base_color=(0.6, 0.45, 0.3)),
        Material(base_color=(0.9, 0.9, 0.9), roughness=0.7),
    ]
    lights = [
        Light(kind="point", position=(2.0, -3.0, 4.0), intensity=120.0, radius=0.25),
        Light(kind="point", position=(-3.0, -1.0, 3.0), intensity=40.0, radius=0.25),
    ]
    return Scene.from_arrays(
        p,
        t,
        normals=sim_core.smooth_normals(p, t),
        material_ids=oid,
        object_ids=oid,
        materials=mats,
        lights=lights,
        environment=(0.25, 0.3, 0.35),
    )


def metrics(img: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    a, b = np.clip(img, 0, 1), np.clip(ref, 0, 1)
    mse = float(np.mean((a - b) ** 2))
    psnr = float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)
    ssim = structural_similarity(a, b, data_range=1.0, channel_axis=2)
    return psnr, 1.0 - float(ssim)


def timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--eye-separation", type=float, default=0.2)
    args = ap.parse_args()
    w, h, th = args.width, args.height, args.threads
    configs = {
        "hard": {"shadow_samples": 1, "ao_samples": 0, "max_depth": 2},  # deterministic shading
        "soft": {"shadow_samples": 4, "ao_samples": 4, "max_depth": 2},  # Monte Carlo noise in 1 spp
    }
    scenes = [
        ("teapot-plane", teapot_on_plane(), teapot_camera(w, h)),
        ("effects", effects_scene(), effects_camera(w, h)),
        ("cow-spot", cow_and_spot(), Camera.look_at((0.0, -6.0, 2.5), (0.0, 0.0, 0.7), (0, 0, 1), 0.6, w, h)),
    ]
    header = (
        f"{'scene':<13} {'cfg':<5} {'mode':<22} {'rays rel':>8} {'samples rel':>11} {'time s':>7} "
        f"{'PSNR dB':>8} {'1-SSIM':>8}"
    )
    print(header)
    print("-" * len(header))
    for (name, scene, cam), (cfg, base) in ((sc, c) for sc in scenes for c in configs.items()):
        ref1, t_ref1 = timed(render, scene, cam, RenderSettings(**base), threads=th)
        rows = [("1spp (reference)", ref1, t_ref1, ref1)]
        for b in (2, 3, 4):
            s = RenderSettings(mode="undersample", block=b, **base)
            r, t = timed(render, scene, cam, s, threads=th)
            rows.append((f"undersample {b}x{b}", r, t, ref1))
        # Multi-rate: third frame of a static view (state from the previous frames).
        s = RenderSettings(mode="undersample", block=2, multirate=True, **base)
        prev = None
        for _ in range(2):
            prev = render(scene, cam, s, threads=th, previous=prev)
        r, t = timed(render, scene, cam, s, threads=th, previous=prev)
        rows.append(("multirate 2..4", r, t, ref1))
        fsaa, t_fsaa = timed(render, scene, cam, RenderSettings(mode="fsaa", **base), threads=th)
        rows.append(("FSAA 2x2 (reference)", fsaa, t_fsaa, fsaa))
        s = RenderSettings(mode="supersample", block=2, **base)
        r, t = timed(render, scene, cam, s, threads=th)
        rows.append(("adaptive super 2x2", r, t, fsaa))
        for label, r, t, ref in rows:
            psnr, dssim = metrics(r.image, ref.image)
            rays = r.counters["rays_total"] / ref.counters["rays_total"]
            samples = r.counters["samples_traced"] / ref.counters["samples_traced"]
            print(
                f"{name:<13} {cfg:<5} {label:<22} {rays:>8.3f} {samples:>11.3f} {t:>7.3f} "
                f"{psnr:>8.2f} {dssim:>8.4f}"
            )
        # Stereo: the right eye by reprojection against a directly traced right eye.
        sep = args.eye_separation
        st, t_st = timed(render_stereo, scene, cam, sep, RenderSettings(**base), threads=th)
        right = render(scene, cam.shifted(sep / 2), RenderSettings(**base), threads=th)
        psnr, dssim = metrics(st.right.image, right.image)
        rays = st.right.counters["rays_total"] / right.counters["rays_total"]
        samples = st.right.counters["samples_traced"] / right.counters["samples_traced"]
        print(
            f"{name:<13} {cfg:<5} {f'stereo right (sep {sep})':<22} {rays:>8.3f} {samples:>11.3f} "
            f"{t_st:>7.3f} "
            f"{psnr:>8.2f} {dssim:>8.4f}   reuse {st.reuse_ratio:.1%} (holes {st.holes}, "
            f"silhouettes {st.silhouettes}, "
            f"depth mismatches {st.depth_mismatches})"
        )


if __name__ == "__main__":
    main()
