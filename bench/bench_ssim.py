"""SSIM: service.metrics.ssim against scikit-image (time and deviation of the mean), same run.

Run: .venv/bin/python bench/bench_ssim.py [--repeats N]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from skimage.metrics import structural_similarity

from service.metrics import ssim


def _best_ms(fn, repeats: int) -> float:
    fn()
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best * 1e3


def _images(h: int, w: int, c: int | None, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    shape = (h, w) if c is None else (h, w, c)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    base = 0.5 + 0.4 * np.sin(9 * x) * np.cos(5 * y)
    a = np.clip((base if c is None else base[..., None]) + 0.05 * rng.standard_normal(shape), 0, 1)
    b = np.clip(a + 0.03 * rng.standard_normal(shape), 0, 1)
    return a, b


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"{'image':>18} {'window':>9} {'ours ms':>9} {'skimage ms':>11} {'speed-up':>9} {'max |diff|':>11}")
    for h, w, c in ((512, 1024, 3), (256, 256, None), (72, 128, 3)):
        for gauss in (False, True):
            kw = {"gaussian_weights": True, "sigma": 1.5, "use_sample_covariance": False} if gauss else {}
            axis = None if c is None else -1
            dev = 0.0
            for seed in range(3):
                a, b = _images(h, w, c, seed)
                ref = structural_similarity(a, b, data_range=1.0, channel_axis=axis, **kw)
                dev = max(dev, abs(ssim(a, b, gaussian_weights=gauss) - ref))
            a, b = _images(h, w, c, 0)
            ours = _best_ms(lambda a=a, b=b, g=gauss: ssim(a, b, gaussian_weights=g), args.repeats)
            sk = _best_ms(lambda a=a, b=b, kw=kw, axis=axis: structural_similarity(
                a, b, data_range=1.0, channel_axis=axis, **kw), max(2, args.repeats // 2))
            name = f"{w}x{h}" + ("" if c is None else f"x{c}")
            win = "gauss 11" if gauss else "box 7"
            print(f"{name:>18} {win:>9} {ours:9.2f} {sk:11.2f} {sk / ours:8.1f}x {dev:11.2e}")


if __name__ == "__main__":
    main()
