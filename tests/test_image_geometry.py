"""The shared image (sim_core.image) and geometry (sim_core.geometry) helpers: the one implementation the
tracer, the evaluator, the loaders, the service's previews and the scene generators use."""

from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from PIL import Image
from sim_core.geometry import smooth_normals
from sim_core.image import (
    encode_exr,
    encode_png,
    linear_to_srgb,
    load_exr,
    srgb_to_linear,
    upsample_bilinear,
    write_exr,
)

import sim_core
from sim_core import Camera, Light, RenderSettings, Scene


# -- image ---------------------------------------------------------------------------------------------
@given(st.floats(0.0, 1.0))
def test_srgb_curves_are_inverse(v: float) -> None:
    assert float(srgb_to_linear(linear_to_srgb(v))) == pytest.approx(v, abs=1e-12)


def test_upsample_keeps_the_tracers_float32_and_is_identity_at_size() -> None:
    img = np.random.default_rng(1).random((3, 5, 3)).astype(np.float32)
    up = upsample_bilinear(img, 6, 10)
    assert up.dtype == np.float32 and up.shape == (6, 10, 3)
    assert img.min() <= up.min() and up.max() <= img.max()
    assert upsample_bilinear(img, 3, 5) is img  # no copy when nothing changes
    assert upsample_bilinear(img.astype(np.float64), 6, 10).dtype == np.float64
    np.testing.assert_allclose(upsample_bilinear(img.astype(np.float64), 6, 10), up, rtol=1e-6)


def test_png_encoding_is_the_display_transform(tmp_path) -> None:
    img = np.array([[[0.0, 0.5, 1.0], [np.nan, np.inf, 7.0]]], dtype=np.float32)
    with Image.open(io.BytesIO(encode_png(img))) as im:
        px = np.asarray(im.convert("RGB"))
    assert px.shape == (1, 2, 3)
    assert px[0, 0].tolist() == [0, round(255 * 0.7353569), 255]
    assert px[0, 1].tolist() == [0, 255, 255]  # NaN black, +Inf and overexposure white


def test_exr_write_encode_and_load_round_trip(tmp_path) -> None:
    sky = np.random.default_rng(0).random((8, 16, 3)).astype(np.float32) * 50.0
    write_exr(tmp_path / "sky.exr", sky)
    np.testing.assert_array_equal(load_exr(tmp_path / "sky.exr"), sky)
    data = encode_exr(sky)
    assert data[:4] == b"\x76\x2f\x31\x01" and data == (tmp_path / "sky.exr").read_bytes()
    (tmp_path / "again.exr").write_bytes(data)
    np.testing.assert_array_equal(load_exr(tmp_path / "again.exr"), sky)


# -- geometry --------------------------------------------------------------------------------------------
def test_smooth_normals_are_unit_or_zero() -> None:
    # a tetrahedron, an unused vertex (4) and two coincident triangles of opposite winding (5, 6, 7)
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5],
                    [3, 0, 0], [4, 0, 0], [3, 1, 0]], dtype=np.float32)
    tri = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [5, 6, 7], [5, 7, 6]])
    n = smooth_normals(pos, tri)
    assert n.dtype == np.float32 and n.shape == pos.shape
    np.testing.assert_allclose(np.linalg.norm(n[:4], axis=1), 1.0, rtol=1e-6)
    assert np.allclose(n[3], [0.0, 0.0, 1.0], atol=0.6) and n[3][2] > 0.5  # apex points up and out
    assert not n[4].any() and not n[5:].any()  # nothing to average: zero, the face normal is used


def test_a_zero_normal_shades_like_the_face() -> None:
    """Why smooth_normals gives zero and not a fixed axis: the tracer shades zero-normal corners with the
    triangle's own normal: a wall with zero normals renders exactly like one without normals."""
    pos = np.array([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]], dtype=np.float32)
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    light = [Light(kind="point", position=(0.0, -3.0, 1.0), intensity=50.0)]
    cam = Camera.look_at((0.0, -4.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.9, 24, 16)
    settings = RenderSettings(mode="1spp", shadow_samples=1, max_depth=0)
    flat = sim_core.render(Scene.from_arrays(pos, tri, lights=light), cam, settings, threads=1).image
    zero = sim_core.render(Scene.from_arrays(pos, tri, normals=np.zeros_like(pos), lights=light), cam,
                           settings, threads=1).image
    assert (flat[8, 12] != flat[0, 0]).any()  # the wall is in view and lit
    np.testing.assert_array_equal(zero, flat)
