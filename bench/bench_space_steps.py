"""Where a scene's setting space jumps in error, and where its dynamic power goes: Max, every single-
parameter step down from Max, candidate in-between values, the Max-Mid preset and a greedy descent to the
cheapest setting within an error budget, all priced as whole frames at display resolution.

Each setting is rendered whole at the display size and priced with the product's own functions (what
``service.display_pricing`` does with ``DisplayPricing("full")``): error = 1 - SSIM after the display
transform against Max at the same size (``service.evaluation.image_error``), power = what the profile's
GPU draws at the frame rate the frame reaches (``service.evaluation._price``). Cameras are path frames
spread evenly along the path.

    .venv/bin/python bench/bench_space_steps.py chess --profile desktop --size 320x180 --cameras 4

Candidate values (``--candidates``) are settings outside the default space, named ``parameter=value``
(the values below); ``--greedy`` also walks down from Max one step at a time (each step the cheapest
single-parameter step down whose mean error over the cameras stays within ``--budget``) and prints the
path it took.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from addon.core.campaign import parse_size
from addon.core.report import preset_indices
from service.camera_path import CameraPath
from service.display_pricing.tracing import Renderer
from service.evaluation import CameraSpec, _price, image_error, read_scene
from service.params import default_space

REPO = Path(__file__).resolve().parent.parent

#: Values outside the default space, as RenderSettings fields (name, fields).
CANDIDATES: tuple[tuple[str, dict[str, Any]], ...] = (
    ("sampling=adaptive_supersample_3x3", {"mode": "supersample", "block": 3}),
    ("sampling=adaptive_supersample_4x4", {"mode": "supersample", "block": 4}),
    ("shadow_samples=8", {"shadow_samples": 8}),
    ("shadow_samples=2", {"shadow_samples": 2}),
    ("ao_samples=12", {"ao_samples": 12}),
    ("ao_samples=2", {"ao_samples": 2}),
    ("resolution_scale=0.95", {"resolution_scale": 0.95}),
)


def built_scene(name: str) -> tuple[Any, CameraPath]:
    """A scene built by ``python -m blend_scenes.build --scene NAME`` and its camera path."""
    d = REPO / "blend_scenes" / "build" / name
    return read_scene(d / "scene.rbscene"), CameraPath.load(d / "path.json")


def cameras(path: CameraPath, n: int, size: tuple[int, int], step: int = 0) -> list[tuple[int, CameraSpec]]:
    """``n`` path frames spread evenly (the middle of ``n`` equal parts), or with ``step`` every
    ``step``-th frame from the first (the main job's evaluated frames)."""
    out = []
    numbers = (range(0, len(path), step) if step > 0 else
               [round((k + 0.5) * (len(path) - 1) / n) for k in range(n)])
    for i in numbers:
        f = path.frames[i]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        out.append((i, CameraSpec(tuple(m[:3, 3]), tuple(-m[:3, 2]), tuple(m[:3, 1]), f.vfov, *size)))
    return out


class Pricer:
    """Whole-frame pricing of RenderSettings at a few cameras, Max rendered once per camera."""

    def __init__(self, scene: Any, cams: list[tuple[int, CameraSpec]], profile: str, fps: float,
                 metric: str, threads: int | None) -> None:
        self.r = Renderer(scene, threads)
        self.cams, self.profile, self.fps, self.metric = cams, profile, fps, metric
        self.space = default_space()
        self.max = self.space.to_settings(self.space.max_quality_indices())
        self.refs = [self.r.frame(c.to_camera(), self.max) for _, c in cams]
        self.seen: dict[tuple, dict[str, Any]] = {}

    def price(self, settings: Any, filtered: bool = False) -> dict[str, Any]:
        """``filtered``: the error after a 3x3 Blackman-Harris pixel filter on the image (what the
        sub-pixel modes' resolve applies, here on one sample a pixel; power unchanged, the filter's own
        cost not counted): how much of a 1-spp mode's error is the missing filter."""
        key = (tuple(sorted(dataclasses.asdict(settings).items())), filtered)
        if key in self.seen:
            return self.seen[key]
        errs, powers, fpss, energy, rays = [], [], [], {}, {}
        for (_, cam), ref in zip(self.cams, self.refs, strict=True):
            res = ref if settings == self.max else self.r.frame(cam.to_camera(), settings)
            img = _pixel_filter(res.image) if filtered else res.image
            errs.append(0.0 if res is ref else image_error(self.metric, ref.image, img))
            p, _, b = _price(res, self.profile, self.fps)
            powers.append(p)
            fpss.append(b["fps"])
            for k, v in b.items():
                if k.startswith("energy_j.") and k != "energy_j.static":
                    energy[k[9:]] = energy.get(k[9:], 0.0) + v / len(self.cams)
            for k in ("rays_primary", "rays_shadow", "rays_ao", "rays_reflection", "rays_refraction"):
                rays[k[5:]] = rays.get(k[5:], 0.0) + res.counters[k] / len(self.cams)
        out = {"errors": errs, "error": float(np.mean(errs)), "power": float(np.mean(powers)),
               "fps": float(np.mean(fpss)), "energy": energy, "rays": rays}
        self.seen[key] = out
        return out


def _pixel_filter(img: np.ndarray) -> np.ndarray:
    """Separable Blackman-Harris filter 1.5 px in radius (Cycles' default, sim_core's resolve) over pixel
    centres: taps at -1, 0, 1 px; edges repeated."""
    def bh(o: float) -> float:
        v = 2.0 * np.pi * (o / 3.0 + 0.5)
        return max(0.0, 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v))
    w = np.array([bh(-1.0), bh(0.0), bh(1.0)])
    w /= w.sum()
    p = np.pad(img, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h = w[0] * p[:, :-2] + w[1] * p[:, 1:-1] + w[2] * p[:, 2:]
    return (w[0] * h[:-2] + w[1] * h[1:-1] + w[2] * h[2:]).astype(np.float32)


def fmt(name: str, r: dict[str, Any], mx: dict[str, Any]) -> str:
    saved = 100.0 * (1.0 - r["power"] / mx["power"])
    top = sorted(r["energy"].items(), key=lambda kv: -kv[1])[:3]
    energy = ", ".join(f"{k} {1000 * v:.0f}" for k, v in top)
    rays = r["rays"]
    kinds = ("primary", "shadow", "ao", "reflection", "refraction")
    ray_s = " / ".join(f"{rays[k] / 1e6:.2f}" for k in kinds)
    errs = r["errors"]
    per_cam = (" ".join(f"{e:.4f}" for e in errs) if len(errs) <= 8 else
               f"max {max(errs):.4f}, {sum(e > 0.02 for e in errs)} of {len(errs)} over 0.02")
    return (f"| {name} | {r['error']:.4f} | {per_cam} | {r['power']:.2f} | {r['fps']:.1f} | {saved:.1f} % | "
            f"{ray_s} | {energy} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--profile", default="desktop")
    ap.add_argument("--size", type=parse_size, default=(320, 180))
    ap.add_argument("--cameras", type=int, default=4)
    ap.add_argument("--frame-step", type=int, default=0,
                    help="every N-th path frame instead of --cameras (the main job: 19 for 1680)")
    ap.add_argument("--no-steps", action="store_true", help="skip the single steps and the Max-Mid preset")
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--metric", default="ssim")
    ap.add_argument("--budget", type=float, default=0.02)
    ap.add_argument("--candidates", action="store_true", help="also price the values outside the space")
    ap.add_argument("--greedy", action="store_true", help="also walk down from Max within --budget")
    ap.add_argument("--extra", nargs="*", default=[],
                    help="further settings as name=FIELD:VALUE,FIELD:VALUE (fields over Max), e.g. "
                         "s4a8=shadow_samples:4,ao_samples:8")
    ap.add_argument("--pixel-filter", action="store_true",
                    help="also each --extra setting's error with a 3x3 Blackman-Harris filter on its image")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    t0 = time.time()
    scene, path = built_scene(args.scene)
    cams = cameras(path, args.cameras, args.size, args.frame_step)
    pr = Pricer(scene, cams, args.profile, args.fps, args.metric, args.threads)
    space = pr.space
    mq = space.max_quality_indices()
    mx = pr.price(pr.max)
    print(f"{args.scene}, {args.size[0]}x{args.size[1]}, profile {args.profile} at {args.fps:g} fps, metric "
          f"{args.metric}; path frames {[i for i, _ in cams]}")
    print("| setting (from Max) | mean error | error per camera | power (W) | fps | saved vs Max | "
          "rays (M): primary / shadow / AO / reflection / refraction | top dynamic energy (mJ/frame) |")
    print("|---|---|---|---|---|---|---|---|")
    print(fmt("Max", mx, mx), flush=True)
    for i, p in enumerate(space.parameters):
        if args.no_steps:
            break
        if mq[i] == 0:
            continue
        idx = list(mq)
        idx[i] = mq[i] - 1
        print(fmt(f"{p.name}={p.values[idx[i]]}", pr.price(space.to_settings(idx)), mx), flush=True)
    counts = [len(p.values) for p in space.parameters]
    mqs = [p.max_quality for p in space.parameters]
    for level, name in () if args.no_steps else ((0.75, "Max-Mid"),):
        idx = preset_indices(counts, mqs, level)
        vals = ", ".join(f"{k}={v}" for k, v in space.values_of(idx).items() if v != space.values_of(mq)[k])
        print(fmt(f"{name} ({vals})", pr.price(space.to_settings(idx)), mx), flush=True)
    if args.candidates:
        for name, fields in CANDIDATES:
            print(fmt(name, pr.price(dataclasses.replace(pr.max, **fields)), mx), flush=True)
    for spec in args.extra:
        name, _, body = spec.partition("=")
        fields: dict[str, Any] = {}
        for kv in body.split(","):
            k, _, v = kv.partition(":")
            fields[k] = _parse_value(v)
        print(fmt(f"{name} ({body})", pr.price(dataclasses.replace(pr.max, **fields)), mx), flush=True)
        if args.pixel_filter:
            filt = pr.price(dataclasses.replace(pr.max, **fields), True)
            print(fmt(f"{name} ({body}), pixel filter", filt, mx), flush=True)
    if args.greedy:
        idx = list(mq)
        cur = mx
        steps = []
        while True:
            best = None
            for i in range(len(space.parameters)):
                if idx[i] == 0:
                    continue
                trial = list(idx)
                trial[i] -= 1
                r = pr.price(space.to_settings(trial))
                if r["error"] <= args.budget and r["power"] < cur["power"] - 1e-6 and (
                        best is None or r["power"] < best[1]["power"]):
                    best = (trial, r, i)
            if best is None:
                break
            idx, cur, i = best
            steps.append(f"{space.parameters[i].name}={space.parameters[i].values[idx[i]]}")
            print(fmt("greedy: " + ", ".join(steps), cur, mx), flush=True)
    print(f"({time.time() - t0:.0f} s)")


def _parse_value(v: str) -> Any:
    for cast in (int, float):
        try:
            return cast(v)
        except ValueError:
            pass
    return {"True": True, "False": False}.get(v, v)


if __name__ == "__main__":
    main()
