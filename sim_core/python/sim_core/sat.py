"""Summed-area tables (thesis ch. 2) from Python: precision of float32 tables, naive against offset.

The native core builds the tables (``SummedAreaTableF32`` models the hardware, ``SummedAreaTableF64`` is
the reference). A naive float32 table grows to W*H*mean and loses the low bits that small box filters need;
an offset table (mean subtracted first) stays near 0 and keeps them. ``sat_precision`` measures that on a
given image with random filter footprints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _core

__all__ = ["EnvironmentFilter", "SatPrecision", "hdr_test_map", "sat_precision", "summed_area_table"]

EnvironmentFilter = _core.EnvironmentFilter


def _check_image(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim not in (2, 3) or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {a.shape}")
    a = np.ascontiguousarray(a, dtype=np.float32)
    if not np.isfinite(a).all():
        raise ValueError("image has NaN or Inf values")
    return a


def summed_area_table(image: np.ndarray, order: int = 1, offset: bool = True, precision: str = "float32"):
    """Build a native summed-area table of ``order`` 1 (box) or 2 (Bartlett) in float32 or float64."""
    a = _check_image(image)
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order}")
    if precision == "float32":
        return _core.SummedAreaTableF32(a, order, offset)
    if precision == "float64":
        return _core.SummedAreaTableF64(a, order, offset)
    raise ValueError(f"precision must be 'float32' or 'float64', got {precision!r}")


def hdr_test_map(width: int = 2048, height: int = 1024, seed: int = 0, sun_peak: float = 5.0e4) -> np.ndarray:
    """A synthetic equirectangular HDR sky (gradient, textured ground, clouds, a sun), (H, W, 3) float32.

    Deterministic. With the default ``sun_peak`` values span ~5 decades like a real outdoor light probe;
    ``sun_peak=0`` gives an overcast sky (the sun's energy then no longer dominates the table).
    """
    rng = np.random.default_rng(seed)
    rows = (np.arange(height, dtype=np.float64) + 0.5) / height  # 0 at the zenith
    cols = (np.arange(width, dtype=np.float64) + 0.5) / width
    polar = rows[:, None] * np.pi
    elev = np.pi / 2 - polar
    sky = np.where(elev > 0, 0.4 + 0.8 * np.exp(-3.0 * elev), 0.05)
    img = np.empty((height, width, 3), dtype=np.float64)
    img[..., 0] = sky * 0.6
    img[..., 1] = sky * 0.8
    img[..., 2] = sky * 1.2
    noise = rng.random((height, width))
    img[..., :] *= (0.8 + 0.4 * noise)[..., None]
    clouds = 0.5 * (1 + np.sin(7 * 2 * np.pi * cols[None, :] + 3 * np.sin(11 * polar)))
    img[..., :] += (np.where(elev > 0.05, clouds * 0.8, 0.0))[..., None]
    su, sv = 0.3, 0.35  # sun position (u, row fraction)
    du = np.minimum(np.abs(cols[None, :] - su), 1 - np.abs(cols[None, :] - su)) * 2 * np.pi
    dv = (rows[:, None] - sv) * np.pi
    d2 = (du * np.sin(sv * np.pi)) ** 2 + dv**2
    img[..., :] += (sun_peak * np.exp(-d2 / (2 * 0.01**2)))[..., None] * np.array([1.0, 0.95, 0.85])
    return img.astype(np.float32)


@dataclass(frozen=True)
class SatPrecision:
    """Errors of float32 tables against float64, over random footprints (relative to the exact mean)."""

    width: int
    height: int
    order: int
    queries: int
    naive_max_abs_table: float  # largest table entry of the naive float32 table
    offset_max_abs_table: float
    naive_mean_rel_error: float
    offset_mean_rel_error: float
    naive_max_rel_error: float
    offset_max_rel_error: float

    @property
    def improvement(self) -> float:
        """Mean relative error of the naive table over the offset table (how much the offset buys)."""
        return self.naive_mean_rel_error / max(self.offset_mean_rel_error, 1e-300)


def sat_precision(image: np.ndarray, order: int = 1, queries: int = 20000, max_radius: int = 8,
                  seed: int = 1) -> SatPrecision:
    """Compare naive and offset float32 tables with a float64 table on random small footprints.

    Order 1: box means over squares of half-width 0..max_radius; order 2: Bartlett means of radius
    1..max_radius. Errors are relative to the float64 reference mean per channel.
    """
    a = _check_image(image)
    h, w = a.shape[:2]
    rng = np.random.default_rng(seed)
    r = rng.integers(0 if order == 1 else 1, max_radius + 1, size=queries)
    cx = rng.integers(max_radius + 1, w - max_radius - 1, size=queries)
    cy = rng.integers(max_radius + 1, h - max_radius - 1, size=queries)
    ref = summed_area_table(a, order, offset=False, precision="float64")
    naive = summed_area_table(a, order, offset=False, precision="float32")
    off = summed_area_table(a, order, offset=True, precision="float32")
    if order == 1:
        q = np.stack([cx - r, cy - r, cx + r + 1, cy + r + 1], axis=1).astype(np.int64)
        norm = ((2 * r + 1) ** 2).astype(np.float64)[:, None]
        f = "box_sums"
    else:
        q = np.stack([cx, cy, r, r], axis=1).astype(np.int64)
        norm = (r.astype(np.float64) ** 4)[:, None]
        f = "bartlett_sums"
    exact = getattr(ref, f)(q) / norm
    denom = np.maximum(np.abs(exact), 1e-6)
    e_naive = np.abs(getattr(naive, f)(q) / norm - exact) / denom
    e_off = np.abs(getattr(off, f)(q) / norm - exact) / denom
    return SatPrecision(
        width=w, height=h, order=order, queries=queries,
        naive_max_abs_table=naive.max_abs(), offset_max_abs_table=off.max_abs(),
        naive_mean_rel_error=float(e_naive.mean()), offset_mean_rel_error=float(e_off.mean()),
        naive_max_rel_error=float(e_naive.max()), offset_max_rel_error=float(e_off.max()),
    )
