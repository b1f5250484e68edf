"""SSIM: native service.metrics.ssim and its numpy twin against scikit-image, same run.

Prints median times over --repeats runs (the machine may be shared: medians, not minima) and the
maximum deviation of the mean SSIM from ``skimage.metrics.structural_similarity`` over three image
pairs per case (float64 input; Gaussian: ``gaussian_weights=True, sigma=1.5,
use_sample_covariance=False``). The float32 rows feed float32 images to our kernel and compare with
scikit-image on the same values widened to float64.

Run: .venv/bin/python bench/bench_ssim.py [--repeats N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
from skimage.metrics import structural_similarity

from service.metrics import ssim, ssim_numpy


def _median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1e3


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
    ap.add_argument("--repeats", type=int, default=9)
    args = ap.parse_args()
    load = os.getloadavg()[0]
    print(f"median of {args.repeats} runs; load average at start {load:.1f}")
    print(f"{'image':>12} {'window':>9} {'dtype':>7} {'native ms':>10} {'numpy ms':>9} {'skimage ms':>11}"
          f" {'x skimage':>10} {'max|d| native':>14} {'max|d| numpy':>13}")
    for h, w, c in ((512, 1024, 3), (256, 256, None), (72, 128, 3)):
        for gauss in (False, True):
            for dtype in (np.float64, np.float32):
                if dtype is np.float32 and (h, w) != (512, 1024):
                    continue
                kw = {"gaussian_weights": True, "sigma": 1.5, "use_sample_covariance": False} if gauss else {}
                axis = None if c is None else -1
                dev_native = dev_numpy = 0.0
                for seed in range(3):
                    a, b = _images(h, w, c, seed)
                    a, b = a.astype(dtype), b.astype(dtype)
                    ref = structural_similarity(a.astype(np.float64), b.astype(np.float64), data_range=1.0,
                                                channel_axis=axis, **kw)
                    dev_native = max(dev_native, abs(ssim(a, b, gaussian_weights=gauss) - ref))
                    dev_numpy = max(dev_numpy, abs(ssim_numpy(a, b, gaussian_weights=gauss) - ref))
                a, b = _images(h, w, c, 0)
                a, b = a.astype(dtype), b.astype(dtype)
                ours = _median_ms(lambda a=a, b=b, g=gauss: ssim(a, b, gaussian_weights=g), args.repeats)
                twin = _median_ms(lambda a=a, b=b, g=gauss: ssim_numpy(a, b, gaussian_weights=g),
                                  max(3, args.repeats // 2))
                sk = _median_ms(lambda a=a, b=b, kw=kw, axis=axis: structural_similarity(
                    a, b, data_range=1.0, channel_axis=axis, **kw), max(3, args.repeats // 2))
                name = f"{w}x{h}" + ("" if c is None else f"x{c}")
                win = "gauss 11" if gauss else "box 7"
                dt = "f32" if dtype is np.float32 else "f64"
                print(f"{name:>12} {win:>9} {dt:>7} {ours:10.2f} {twin:9.2f} {sk:11.2f} {sk / ours:9.1f}x"
                      f" {dev_native:14.2e} {dev_numpy:13.2e}")


if __name__ == "__main__":
    main()
