"""SSIM agrees with scikit-image; PSNR; FLIP; constant and invalid images."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skimage.metrics import structural_similarity

from service.metrics import flip, psnr, ssim, ssim_numpy
from sim_core import _core


def _natural(h: int, w: int, seed: int) -> np.ndarray:
    """Smooth gradients, edges and a little noise, like a rendered frame."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    img = np.stack([0.5 + 0.4 * np.sin(6 * x + c) * np.cos(4 * y) for c in range(3)], axis=-1)
    img[h // 3: h // 2, w // 4: w // 2] = [0.9, 0.2, 0.1]
    return np.clip(img + 0.02 * rng.standard_normal(img.shape), 0, 1)


def _pairs():
    rng = np.random.default_rng(3)
    a = rng.random((61, 83, 3))
    yield "random", a, np.clip(a + 0.2 * rng.standard_normal(a.shape), 0, 1)
    n = _natural(96, 128, 1)
    yield "natural", n, np.clip(n + 0.05 * rng.standard_normal(n.shape), 0, 1)
    yield "natural-blur", n, (n + np.roll(n, 1, axis=1) + np.roll(n, 1, axis=0)) / 3
    yield "gray", n[..., 0], n[..., 1]
    c = np.full((40, 50, 3), 0.25)
    yield "constant-same", c, c
    yield "constant-diff", c, c + 0.3
    yield "near-constant", c, c + 1e-9 * rng.standard_normal(c.shape)
    yield "tiny", rng.random((7, 7)), rng.random((7, 7))


@pytest.mark.parametrize("case", list(_pairs()), ids=lambda c: c[0])
@pytest.mark.parametrize("gaussian", [False, True])
def test_ssim_matches_skimage(case, gaussian: bool) -> None:
    _, a, b = case
    if gaussian and min(a.shape[:2]) < 11:
        with pytest.raises(ValueError):
            ssim(a, b, gaussian_weights=True)
        return
    kw = {"gaussian_weights": True, "sigma": 1.5, "use_sample_covariance": False} if gaussian else {}
    ref = structural_similarity(a, b, data_range=1.0, channel_axis=-1 if a.ndim == 3 else None, **kw)
    ours = ssim(a, b, data_range=1.0, gaussian_weights=gaussian)
    assert math.isfinite(ours)
    assert ours == pytest.approx(ref, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(h=st.integers(7, 70), w=st.integers(7, 70), c=st.sampled_from([None, 1, 2, 3, 4]),
       gaussian=st.booleans(), noise=st.sampled_from([0.0, 1e-9, 1e-3, 0.2, 1.0]),
       offset=st.sampled_from([0.0, 0.5, 1e3]), data_range=st.sampled_from([1.0, 255.0]),
       seed=st.integers(0, 2**32 - 1))
def test_native_ssim_matches_numpy_twin(h, w, c, gaussian, noise, offset, data_range, seed) -> None:
    """The native kernel against the independent numpy twin: tiny, odd and non-multiple-of-band sizes,
    constant to noisy images, large offsets (cancellation in the variances)."""
    win = 11 if gaussian else 7
    rng = np.random.default_rng(seed)
    shape = (h, w) if c is None else (h, w, c)
    a = offset + rng.random(shape)
    b = a + noise * rng.standard_normal(shape)
    if min(h, w) < win:
        with pytest.raises(ValueError):
            ssim(a, b, data_range=data_range, gaussian_weights=gaussian)
        return
    ours = ssim(a, b, data_range=data_range, gaussian_weights=gaussian)
    twin = ssim_numpy(a, b, data_range=data_range, gaussian_weights=gaussian)
    assert math.isfinite(ours)
    # Both (like scikit-image) take variances as E[x^2] - E[x]^2: rounding of ~eps * peak^2 in the sums
    # of squares, divided by C2 = (0.03 * data_range)^2, bounds how far two correct codes may differ.
    peak = max(np.abs(a).max(), np.abs(b).max())
    tol = 1e-9 + 1e-15 * (peak / data_range) ** 2 / 0.03**2
    assert ours == pytest.approx(twin, abs=tol)


@pytest.mark.parametrize("gaussian", [False, True])
def test_native_ssim_large_image_threads_and_dtypes(gaussian: bool) -> None:
    """A large image (several bands per thread): skimage agreement, identical result for any thread
    count (band sums are added in band order), float32 and non-contiguous input."""
    a = _natural(301, 517, 5)
    rng = np.random.default_rng(6)
    b = np.clip(a + 0.05 * rng.standard_normal(a.shape), 0, 1)
    kw = {"gaussian_weights": True, "sigma": 1.5, "use_sample_covariance": False} if gaussian else {}
    ref = structural_similarity(a, b, data_range=1.0, channel_axis=-1, **kw)
    ours = ssim(a, b, gaussian_weights=gaussian)
    assert ours == pytest.approx(ref, abs=1e-12)
    one = _core.ssim_mean(a, b, 1.0, gaussian, 1)
    assert all(_core.ssim_mean(a, b, 1.0, gaussian, t) == one for t in (2, 3, 8))
    a32, b32 = a.astype(np.float32), b.astype(np.float32)
    ref32 = structural_similarity(a32.astype(np.float64), b32.astype(np.float64), data_range=1.0,
                                  channel_axis=-1, **kw)
    assert ssim(a32, b32, gaussian_weights=gaussian) == pytest.approx(ref32, abs=1e-12)
    at, bt = a.transpose(1, 0, 2), b.transpose(1, 0, 2)  # not C-contiguous: converted in Python
    ref_t = structural_similarity(at, bt, data_range=1.0, channel_axis=-1, **kw)
    assert ssim(at, bt, gaussian_weights=gaussian) == pytest.approx(ref_t, abs=1e-12)
    a8 = (a * 255).astype(np.uint8)
    b8 = (b * 255).astype(np.uint8)
    ref8 = structural_similarity(a8.astype(np.float64), b8.astype(np.float64), data_range=255.0,
                                 channel_axis=-1, **kw)
    assert ssim(a8, b8, data_range=255.0, gaussian_weights=gaussian) == pytest.approx(ref8, abs=1e-12)


def test_ssim_data_range_and_identity() -> None:
    a = _natural(32, 48, 2) * 255
    b = np.clip(a + 10, 0, 255)
    ref = structural_similarity(a, b, data_range=255.0, channel_axis=-1)
    assert ssim(a, b, data_range=255.0) == pytest.approx(ref, abs=1e-6)
    assert ssim(a, a, data_range=255.0) == pytest.approx(1.0)
    assert ssim(a.astype(np.float32), b.astype(np.float32), data_range=255.0) == pytest.approx(ref, abs=1e-6)


@pytest.mark.parametrize("bad", ["nan", "inf", "shape", "small", "range", "nan32", "overflow", "complex"])
def test_ssim_rejects_bad_input(bad: str) -> None:
    a = np.zeros((16, 16, 3))
    b = a.copy()
    kw = {}
    if bad == "nan":
        b[3, 3, 1] = np.nan
    elif bad == "inf":
        a[0, 0, 0] = np.inf
    elif bad == "shape":
        b = np.zeros((16, 15, 3))
    elif bad == "nan32":
        a = np.zeros((40, 30, 3), np.float32)
        b = a.copy()
        b[39, 29, 2] = np.nan  # last pixel: only the last window sees it
    elif bad == "overflow":
        a = np.full((16, 16), 1e200)
        b = np.zeros((16, 16))
    elif bad == "complex":
        a = b = np.zeros((16, 16), complex)
    elif bad == "small":
        a = b = np.zeros((6, 30))
    else:
        kw = {"data_range": 0.0}
    with pytest.raises(ValueError):
        ssim(a, b, **kw)


def test_psnr_and_flip() -> None:
    a = _natural(32, 32, 4)
    b = np.clip(a + 0.01, 0, 1)
    mse = np.mean((a - b) ** 2)
    assert psnr(a, b) == pytest.approx(10 * math.log10(1 / mse))
    assert psnr(a, a) == math.inf
    with pytest.raises(ValueError):
        psnr(a, np.full_like(a, np.nan))
    f_same = flip(a, a)
    f_diff = flip(a, np.clip(a + 0.2, 0, 1))
    assert f_same == pytest.approx(0.0, abs=1e-6) and f_diff > 0.01
