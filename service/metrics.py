"""Image error metrics: fast SSIM matching scikit-image, PSNR, and NVIDIA FLIP when installed.

SSIM follows ``skimage.metrics.structural_similarity`` exactly: K1 = 0.01, K2 = 0.03, a 7x7 uniform
window with sample covariance (N / (N - 1)) by default, or an 11-tap Gaussian (sigma 1.5, truncate 3.5)
with population covariance as in Wang et al. 2004 (skimage's ``gaussian_weights=True,
use_sample_covariance=False``); the mean is taken over the image without a border of half a window,
so only windows that lie fully inside the image count and no edge padding is needed. Colour images are
averaged over channels (skimage's ``channel_axis=-1``).

Speed comes from computing only those interior windows, with float64 running sums along each axis
(separable box filter: one cumulative sum and one difference per axis), and one pass over the stacked
quantities, in cache-sized strips of rows. float64 matters: sums of squares in float32 lose the
variance to cancellation.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

K1 = 0.01
K2 = 0.03
UNIFORM_WIN = 7
GAUSS_SIGMA = 1.5
GAUSS_TRUNCATE = 3.5

def _check_pair(reference: Any, test: Any) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(reference)
    y = np.asarray(test)
    if x.shape != y.shape:
        raise ValueError(f"images differ in shape: {x.shape} vs {y.shape}")
    if x.ndim not in (2, 3):
        raise ValueError(f"expected H x W or H x W x C images, got shape {x.shape}")
    if not (np.issubdtype(x.dtype, np.number) and np.issubdtype(y.dtype, np.number)):
        raise ValueError("images must be numeric")
    x = x.astype(np.float64, copy=False)
    y = y.astype(np.float64, copy=False)
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise ValueError("images contain NaN or Inf")
    return x, y


def _box7(a: np.ndarray, axis: int) -> np.ndarray:
    """Sum over every full 7-sample window along ``axis`` by doubling (2, 4, then 4 + 2 + 1)."""
    n = a.shape[axis]
    m = n - 6

    def sl(arr: np.ndarray, start: int, length: int) -> np.ndarray:
        idx = [slice(None)] * arr.ndim
        idx[axis] = slice(start, start + length)
        return arr[tuple(idx)]

    s2 = sl(a, 0, n - 1) + sl(a, 1, n - 1)
    s4 = sl(s2, 0, n - 3) + sl(s2, 2, n - 3)
    out = sl(s4, 0, m) + sl(s2, 4, m)
    out += sl(a, 6, m)
    return out


def _gauss_kernel() -> np.ndarray:
    r = int(GAUSS_TRUNCATE * GAUSS_SIGMA + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / GAUSS_SIGMA) ** 2)
    return k / k.sum()


_GAUSS = _gauss_kernel()


def _corr_valid(a: np.ndarray, axis: int, k: np.ndarray) -> np.ndarray:
    """Correlation with the symmetric kernel ``k`` over full windows along ``axis`` (taps paired)."""
    n = a.shape[axis]
    w = k.size
    m = n - w + 1
    r = w // 2

    def sl(i: int) -> np.ndarray:
        idx = [slice(None)] * a.ndim
        idx[axis] = slice(i, i + m)
        return a[tuple(idx)]

    out = sl(r) * k[r]
    for i in range(r):
        out += (sl(i) + sl(w - 1 - i)) * k[i]
    return out


_STRIP_ROWS = 32


def _ssim_sum(x: np.ndarray, y: np.ndarray, data_range: float, gaussian: bool) -> tuple[float, int]:
    """Sum and count of the SSIM map of one 2-D channel over its interior windows (float64).

    Works in horizontal strips of a few dozen rows so the five filtered quantities stay in cache."""
    win = _GAUSS.size if gaussian else UNIFORM_WIN
    h = x.shape[0]
    c1 = (K1 * data_range) ** 2
    c2 = (K2 * data_range) ** 2
    n = float(win * win)
    cov_norm = 1.0 if gaussian else n / (n - 1.0)
    total = 0.0
    count = 0
    for r0 in range(0, h - win + 1, _STRIP_ROWS):
        r1 = min(r0 + _STRIP_ROWS, h - win + 1) + win - 1
        xs = x[r0:r1]
        ys = y[r0:r1]
        st = np.empty((5, *xs.shape))
        st[0] = xs
        st[1] = ys
        np.multiply(xs, xs, out=st[2])
        np.multiply(ys, ys, out=st[3])
        np.multiply(xs, ys, out=st[4])
        if gaussian:
            f = _corr_valid(_corr_valid(st, 1, _GAUSS), 2, _GAUSS)
        else:
            f = _box7(_box7(st, 1), 2)
            f *= 1.0 / n
        ux, uy, uxx, uyy, uxy = f
        uxuy = ux * uy
        uxux = ux * ux
        uyuy = uy * uy
        num = (2.0 * uxuy + c1) * (2.0 * cov_norm * (uxy - uxuy) + c2)
        den = (uxux + uyuy + c1) * (cov_norm * ((uxx - uxux) + (uyy - uyuy)) + c2)
        total += float(np.sum(num / den, dtype=np.float64))
        count += num.size
    return total, count


def ssim(reference: Any, test: Any, data_range: float = 1.0, gaussian_weights: bool = False) -> float:
    """Mean structural similarity of two H x W or H x W x C images (channels averaged).

    Equals ``skimage.metrics.structural_similarity(reference, test, data_range=data_range,
    channel_axis=-1)`` on float64 input (and with ``gaussian_weights=True, sigma=1.5,
    use_sample_covariance=False`` for the Gaussian option) to ~1e-12. Constant images give finite
    values (1 for identical ones); NaN or Inf input raises ``ValueError``."""
    x, y = _check_pair(reference, test)
    if not (math.isfinite(data_range) and data_range > 0):
        raise ValueError(f"data_range must be positive and finite, got {data_range}")
    win = _GAUSS.size if gaussian_weights else UNIFORM_WIN
    if min(x.shape[0], x.shape[1]) < win:
        raise ValueError(f"images must be at least {win}x{win} pixels for SSIM, got {x.shape[:2]}")
    if x.ndim == 2:
        t, c = _ssim_sum(x, y, data_range, gaussian_weights)
        return t / c
    vals = []
    for ch in range(x.shape[2]):
        t, c = _ssim_sum(np.ascontiguousarray(x[..., ch]), np.ascontiguousarray(y[..., ch]), data_range,
                         gaussian_weights)
        vals.append(t / c)
    return float(np.mean(vals))


def psnr(reference: Any, test: Any, data_range: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB (``inf`` for identical images)."""
    x, y = _check_pair(reference, test)
    if not (math.isfinite(data_range) and data_range > 0):
        raise ValueError("data_range must be positive and finite")
    mse = float(np.mean((x - y) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(data_range * data_range / mse)


def flip(reference: Any, test: Any, pixels_per_degree: float = 67.0) -> float:
    """Mean LDR-FLIP error of two H x W x 3 images in [0, 1] (needs the ``flip-evaluator`` package)."""
    x, y = _check_pair(reference, test)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ValueError("FLIP needs H x W x 3 images")
    try:
        import flip_evaluator
    except ImportError as exc:  # optional metric
        raise RuntimeError("FLIP needs the optional flip-evaluator package") from exc
    ref = np.ascontiguousarray(np.clip(x, 0, 1), dtype=np.float32)
    tst = np.ascontiguousarray(np.clip(y, 0, 1), dtype=np.float32)
    _, mean_error, _ = flip_evaluator.evaluate(ref, tst, "LDR", parameters={"ppd": pixels_per_degree})
    return float(mean_error)


METRICS = ("ssim", "psnr", "flip")
