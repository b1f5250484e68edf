"""SSIM agrees with scikit-image; PSNR; FLIP; constant and invalid images."""

from __future__ import annotations

import math

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from service.metrics import flip, psnr, ssim


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


def test_ssim_data_range_and_identity() -> None:
    a = _natural(32, 48, 2) * 255
    b = np.clip(a + 10, 0, 255)
    ref = structural_similarity(a, b, data_range=255.0, channel_axis=-1)
    assert ssim(a, b, data_range=255.0) == pytest.approx(ref, abs=1e-6)
    assert ssim(a, a, data_range=255.0) == pytest.approx(1.0)
    assert ssim(a.astype(np.float32), b.astype(np.float32), data_range=255.0) == pytest.approx(ref, abs=1e-6)


@pytest.mark.parametrize("bad", ["nan", "inf", "shape", "small", "range"])
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
