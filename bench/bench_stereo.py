"""Stereo rendering with and without reprojection on the modelled mobile RT GPU (stereo seed, Fig. 3).

Without reprojection both eyes are ray traced; with it the right eye reuses the left eye's shading where the
reprojection test passes and traces only the bad pixels (render_stereo). Both pairs are priced on the mobile
profile: performance = 1 / (left + right frame time), energy = dynamic energy of both eyes plus static
power over their frame time (the energy to produce one stereo pair at full speed). Also the T&I unit alone
(the seed's Fig. 3 is for the T&I unit), the share of right-eye pixels reused (seed: 91.5 %), and the PSNR
of the reprojected right eye against the traced one.

Seed figures: 1.64x performance, 20 % energy saved, 91.5 % reused. Target here: >= 1.4x, >= 15 %.

The G-buffer prefetch is priced three ways, because it decides the result: (a) as the tracer counts it
(every right tile fetches the left-eye texels its frustum can reach between the nearest and farthest left
depth, clamped to the image; sim_core/stereo.h),
(b) each row fetched once per band of tiles and kept on chip (H * W * 32 B per frame), (c) each tile fetching
only the span reprojection can reach (h * (w + max disparity) * 32 B; max disparity = IPD * focal / nearest
left-eye depth). (b) and (c) are what-ifs computed here from the same render, not tracer counters.

Run: .venv/bin/python bench/bench_stereo.py [--width 640] [--frames 3] [--scenes DIR]
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from bench_adaptive import SCENES, cameras, ensure_scenes, psnr

from sim_core import RenderSettings, Scene, load_profile, price, render, render_stereo

DEFAULT_SCENES = Path(__file__).resolve().parent.parent / "blend_scenes" / "build"
GBUFFER_TEXEL_BYTES = 32  # the tracer's kGBufferTexelBytes


def with_prefetch(result, prefetch_bytes: int) -> SimpleNamespace:
    """The same render with another G-buffer prefetch byte count (for the what-if pricing)."""
    c = dict(result.counters)
    c["gbuffer_prefetch_bytes"] = int(prefetch_bytes)
    return SimpleNamespace(counters=c, comparator_histogram=result.comparator_histogram,
                           settings=result.settings)


def prefetch_alternatives(st, cam, ipd: float) -> tuple[int, int]:
    """(b) rows once per tile band, (c) per-tile disparity span, in bytes."""
    w, h = st.right.render_resolution
    rows_once = h * w * GBUFFER_TEXEL_BYTES
    depth = np.asarray(st.left.aovs["depth"])
    near = float(depth[np.isfinite(depth)].min()) if np.isfinite(depth).any() else math.inf
    focal = h / (2 * math.tan(cam.vfov / 2))
    dmax = 0 if not math.isfinite(near) else math.ceil(ipd * focal / max(near, 1e-6)) + 1
    span = sum(t["height"] * min(w, t["width"] + dmax) for t in st.right.tile_stats) * GBUFFER_TEXEL_BYTES
    return rows_once, span


def row(name: str, m: dict[str, float]) -> str:
    cells = [name, f"{100 * m['reuse']:.1f} %"]
    for tag in ("", "_b", "_c"):
        e = m["energy" + tag]
        cells += [f"{m['perf' + tag]:.2f}x", f"{e:.2f} ({100 * (1 - e):.0f} % saved)"]
    cells += [f"{m['tperf']:.2f}x", f"{m['tenergy']:.2f}", f"{m['psnr']:.1f}"]
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--ipd", type=float, default=0.064, help="eye separation in scene units (m)")
    ap.add_argument("--scenes", type=Path, default=DEFAULT_SCENES)
    args = ap.parse_args()
    ensure_scenes(args.scenes, SCENES)
    prof = load_profile("mobile")
    settings = RenderSettings(mode="1spp")
    print(f"## Stereo with/without reprojection, mobile profile, {args.width} px per eye, IPD {args.ipd} m")
    print("| scene | reused | GPU perf (a) | GPU energy (a) | GPU perf (b) | GPU energy (b) | GPU perf (c) | "
          "GPU energy (c) | T&I perf | T&I energy | right-eye PSNR dB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    t0 = time.perf_counter()
    for name in SCENES:
        scene = Scene.from_gltf(args.scenes / name / "scene.glb")
        keys = ("reuse", "perf", "energy", "perf_b", "energy_b", "perf_c", "energy_c", "tperf", "tenergy",
                "psnr")
        acc: dict[str, list[float]] = {k: [] for k in keys}
        for cam in cameras(args.scenes / name / "path.json", args.width, args.frames):
            left = render(scene, cam.shifted(-args.ipd / 2), settings, cache=prof.cache)
            right = render(scene, cam.shifted(args.ipd / 2), settings, cache=prof.cache)
            st = render_stereo(scene, cam, args.ipd, settings, cache=prof.cache)
            pl, pr = price(left, prof, 30, scene=scene), price(right, prof, 30, scene=scene)
            sl, sr = price(st.left, prof, 30, scene=scene), price(st.right, prof, 30, scene=scene)

            def pair(a, b):
                t = a.frame_time_s + b.frame_time_s
                e = a.dynamic_energy_j + b.dynamic_energy_j + prof.static_power_w * t
                ti_t = a.unit_time_s["ti"] + b.unit_time_s["ti"]
                ti_e = sum(x.unit_energy_j["ti"] for x in (a, b))
                return t, e, ti_t, ti_e

            t_no, e_no, tt_no, te_no = pair(pl, pr)
            t_re, e_re, tt_re, te_re = pair(sl, sr)
            b_bytes, c_bytes = prefetch_alternatives(st, cam, args.ipd)
            for tag, nbytes in (("b", b_bytes), ("c", c_bytes)):
                alt = price(with_prefetch(st.right, nbytes), prof, 30, scene=scene)
                t_alt, e_alt, _, _ = pair(sl, alt)
                acc["perf_" + tag].append(t_no / t_alt)
                acc["energy_" + tag].append(e_alt / e_no)
            acc["reuse"].append(st.reuse_ratio)
            acc["perf"].append(t_no / t_re)
            acc["energy"].append(e_re / e_no)
            acc["tperf"].append(tt_no / tt_re)
            acc["tenergy"].append(te_re / te_no)
            acc["psnr"].append(psnr(right.image, st.right.image))
        m = {k: float(np.mean(v)) for k, v in acc.items()}
        rows.append(m)
        print(row(name, m))
    mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}
    print(row("**mean**", mean))
    print(f"\n(total bench time {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
