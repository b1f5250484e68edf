"""Image error metrics: fast SSIM matching scikit-image, PSNR, and NVIDIA FLIP when installed.

SSIM follows ``skimage.metrics.structural_similarity`` exactly: K1 = 0.01, K2 = 0.03, a 7x7 uniform
window with sample covariance (N / (N - 1)) by default, or an 11-tap Gaussian (sigma 1.5, truncate 3.5)
with population covariance as in Wang et al. 2004 (skimage's ``gaussian_weights=True,
use_sample_covariance=False``); the mean is taken over the image without a border of half a window,
so only windows that lie fully inside the image count and no edge padding is needed. Colour images are
averaged over channels (skimage's ``channel_axis=-1``).

``ssim`` runs the native kernel ``sim_core._core.ssim_mean`` (C++, float64 running window sums in
bands of rows, all cores, GIL released; float32 or float64 input without a copy). ``ssim_numpy`` is
its slower numpy twin, kept as an independent reference for tests: it computes only the interior
windows too, with float64 separable window sums (box sums by doubling, Gaussian taps paired) on four
stacked quantities (SSIM needs only the sum of the two variances). float64 matters in both: sums of
squares in float32 lose the variance to cancellation.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from sim_core import _core

K1 = 0.01
K2 = 0.03
UNIFORM_WIN = 7
GAUSS_SIGMA = 1.5
GAUSS_TRUNCATE = 3.5

def _check_shapes(reference: Any, test: Any) -> tuple[np.ndarray, np.ndarray]:
    """Two real-valued H x W or H x W x C images of the same shape (values not yet checked)."""
    x = np.asarray(reference)
    y = np.asarray(test)
    if x.shape != y.shape:
        raise ValueError(f"images differ in shape: {x.shape} vs {y.shape}")
    if x.ndim not in (2, 3):
        raise ValueError(f"expected H x W or H x W x C images, got shape {x.shape}")
    if not (np.issubdtype(x.dtype, np.number) and np.issubdtype(y.dtype, np.number)):
        raise ValueError("images must be numeric")
    if np.iscomplexobj(x) or np.iscomplexobj(y):
        raise ValueError("images must be real")
    return x, y


def _check_pair(reference: Any, test: Any) -> tuple[np.ndarray, np.ndarray]:
    x, y = _check_shapes(reference, test)
    x = x.astype(np.float64, copy=False)
    y = y.astype(np.float64, copy=False)
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise ValueError("images contain NaN or Inf")
    return x, y


def _gauss_kernel() -> np.ndarray:
    r = int(GAUSS_TRUNCATE * GAUSS_SIGMA + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / GAUSS_SIGMA) ** 2)
    return k / k.sum()


_GAUSS = _gauss_kernel()
_STRIP_ELEMENTS = 32768  # per quantity and strip: keeps a strip's working set in the CPU cache
_PARALLEL_ELEMENTS = 300_000  # images this large are split over two threads (numpy releases the GIL)
_pool: ThreadPoolExecutor | None = None


def _filter_axis(src: np.ndarray, axis: int, gaussian: bool, out: np.ndarray, tmp: np.ndarray,
                 tmp2: np.ndarray) -> None:
    """Full-window filter along ``axis`` of ``src`` into ``out`` (length shrinks by window - 1).

    Box: window sums by doubling (2, 4, then 4 + 2 + 1 samples). Gaussian: symmetric taps paired."""
    n = src.shape[axis]

    def sl(arr: np.ndarray, start: int, length: int) -> np.ndarray:
        idx = [slice(None)] * arr.ndim
        idx[axis] = slice(start, start + length)
        return arr[tuple(idx)]

    if not gaussian:
        m = n - 6
        s2 = sl(tmp, 0, n - 1)
        np.add(sl(src, 0, n - 1), sl(src, 1, n - 1), out=s2)
        s4 = sl(tmp2, 0, n - 3)
        np.add(sl(s2, 0, n - 3), sl(s2, 2, n - 3), out=s4)
        np.add(sl(s4, 0, m), sl(s2, 4, m), out=out)
        out += sl(src, 6, m)
        return
    w = _GAUSS.size
    r = w // 2
    m = n - w + 1
    np.multiply(sl(src, r, m), _GAUSS[r], out=out)
    pair = sl(tmp, 0, m)
    for i in range(r):
        np.add(sl(src, i, m), sl(src, w - 1 - i, m), out=pair)
        pair *= _GAUSS[i]
        out += pair


def _ssim_rows(x: np.ndarray, y: np.ndarray, row_ranges: list[tuple[int, int]], data_range: float,
               gaussian: bool) -> float:
    """Sum of the SSIM map over output rows in ``row_ranges`` of (H, W, C) float64 images.

    Four filtered quantities suffice: mean x, mean y, mean (x^2 + y^2) and mean xy, because SSIM only
    uses the sum of the two variances. All buffers are allocated once per call and reused per strip."""
    win = _GAUSS.size if gaussian else UNIFORM_WIN
    _, w, c = x.shape
    strip = max(r1 - r0 for r0, r1 in row_ranges)
    rows_in = strip + win - 1
    wo = w - win + 1
    q = np.empty((4, rows_in, w, c))
    t1 = np.empty((4, rows_in, w, c))
    t2 = np.empty((4, rows_in, w, c))
    rf = np.empty((4, strip, w, c))
    f = np.empty((4, strip, wo, c))
    b1, b2, b3 = (np.empty((strip, wo, c)) for _ in range(3))
    c1 = (K1 * data_range) ** 2
    c2 = (K2 * data_range) ** 2
    n = float(win * win)
    cov = 1.0 if gaussian else n / (n - 1.0)
    scale = 1.0 if gaussian else 1.0 / n
    total = 0.0
    for r0, r1 in row_ranges:
        rows = r1 - r0
        nin = rows + win - 1
        xs, ys = x[r0:r0 + nin], y[r0:r0 + nin]
        qq = q[:, :nin]
        qq[0] = xs
        qq[1] = ys
        np.multiply(xs, xs, out=qq[2])
        np.multiply(ys, ys, out=qq[3])
        qq[2] += qq[3]
        np.multiply(xs, ys, out=qq[3])
        rr = rf[:, :rows]
        _filter_axis(qq, 1, gaussian, rr, t1[:, :nin], t2[:, :nin])
        ff = f[:, :rows]
        _filter_axis(rr, 2, gaussian, ff, t1[:, :rows], t2[:, :rows])
        if scale != 1.0:
            ff *= scale
        ux, uy, uss, uxy = ff
        a1, a2, a3 = b1[:rows], b2[:rows], b3[:rows]
        np.multiply(ux, uy, out=a1)
        np.subtract(uxy, a1, out=a2)  # covariance (times 1/cov)
        a2 *= 2.0 * cov
        a2 += c2
        a1 *= 2.0
        a1 += c1
        a1 *= a2  # numerator
        np.multiply(ux, ux, out=a2)
        np.multiply(uy, uy, out=a3)
        a2 += a3  # ux^2 + uy^2
        np.subtract(uss, a2, out=a3)  # sum of variances (times 1/cov)
        a3 *= cov
        a3 += c2
        a2 += c1
        a2 *= a3  # denominator
        a1 /= a2
        total += float(a1.sum(dtype=np.float64))
    return total


def ssim(reference: Any, test: Any, data_range: float = 1.0, gaussian_weights: bool = False) -> float:
    """Mean structural similarity of two H x W or H x W x C images (channels averaged), native kernel.

    Equals ``skimage.metrics.structural_similarity(reference, test, data_range=data_range,
    channel_axis=-1)`` computed in float64 (and with ``gaussian_weights=True, sigma=1.5,
    use_sample_covariance=False`` for the Gaussian option) to ~1e-15; float32 input is read as is and
    summed in float64. Constant images give finite values (1 for identical ones); NaN or Inf input
    raises ``ValueError``."""
    x, y = _check_shapes(reference, test)
    if not (math.isfinite(data_range) and data_range > 0):
        raise ValueError(f"data_range must be positive and finite, got {data_range}")
    win = _GAUSS.size if gaussian_weights else UNIFORM_WIN
    if min(x.shape[0], x.shape[1]) < win or (x.ndim == 3 and x.shape[2] < 1):
        raise ValueError(f"images must be at least {win}x{win} pixels for SSIM, got {x.shape}")
    dtype = np.float32 if x.dtype == np.float32 and y.dtype == np.float32 else np.float64
    x = np.ascontiguousarray(x, dtype=dtype)
    y = np.ascontiguousarray(y, dtype=dtype)
    value = _core.ssim_mean(x, y, float(data_range), bool(gaussian_weights))
    if not math.isfinite(value):
        # Every pixel lies in a full window, so NaN/Inf input always reaches the mean; check only then.
        if not (np.isfinite(x).all() and np.isfinite(y).all()):
            raise ValueError("images contain NaN or Inf")
        raise ValueError("SSIM overflowed: image values too large for float64 sums of squares")
    return value


def ssim_numpy(reference: Any, test: Any, data_range: float = 1.0, gaussian_weights: bool = False) -> float:
    """Numpy twin of ``ssim`` (same definition, independent code), the reference for the native kernel.

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
        x, y = x[..., None], y[..., None]
    x = np.ascontiguousarray(x)
    y = np.ascontiguousarray(y)
    h, w, c = x.shape
    ho = h - win + 1
    strip = max(4, min(ho, _STRIP_ELEMENTS // (w * c)))
    ranges = [(r0, min(r0 + strip, ho)) for r0 in range(0, ho, strip)]
    if x.size >= _PARALLEL_ELEMENTS and len(ranges) >= 4:
        global _pool
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="ssim")
        half = len(ranges) // 2
        parts = list(_pool.map(lambda rs: _ssim_rows(x, y, rs, data_range, gaussian_weights),
                               (ranges[:half], ranges[half:])))
        total = parts[0] + parts[1]
    else:
        total = _ssim_rows(x, y, ranges, data_range, gaussian_weights)
    return total / (ho * (w - win + 1) * c)


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
        import flip_evaluator  # lazy: an optional package (the test extra)
    except ImportError as exc:  # optional metric
        raise RuntimeError("FLIP needs the optional flip-evaluator package") from exc
    ref = np.ascontiguousarray(np.clip(x, 0, 1), dtype=np.float32)
    tst = np.ascontiguousarray(np.clip(y, 0, 1), dtype=np.float32)
    _, mean_error, _ = flip_evaluator.evaluate(ref, tst, "LDR", parameters={"ppd": pixels_per_degree})
    return float(mean_error)


METRICS = ("ssim", "psnr", "flip")
