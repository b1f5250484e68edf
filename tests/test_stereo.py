"""Stereo by reprojection: reuse, bad-pixel detection, agreement with a directly traced right eye."""

from __future__ import annotations

import numpy as np
import pytest
from tracer_scenes import effects_camera, effects_scene, teapot_camera, teapot_on_plane

from sim_core import RenderSettings, render, render_stereo


@pytest.fixture(scope="module")
def teapot():
    return teapot_on_plane(roughness=0.9)


def test_zero_separation_reuses_everything_and_equals_left(teapot):
    cam = teapot_camera(96, 64)
    st = render_stereo(teapot, cam, 0.0, RenderSettings(), threads=2)
    assert st.reuse_ratio == 1.0
    np.testing.assert_array_equal(st.right.image, st.left.image)
    assert st.right.counters["samples_reused"] == 96 * 64 and st.right.counters["rays_total"] == 0
    assert np.all(st.right.aovs["sample_kind"] == 2)
    # The left eye is an ordinary render from the same place.
    np.testing.assert_array_equal(st.left.image, render(teapot, cam, RenderSettings(), threads=2).image)


def test_typical_separation_reuses_most_and_matches_direct_render(teapot):
    cam = teapot_camera(160, 120)
    sep = 0.2  # scene units: the teapot is ~6 wide, so a human-scale stereo baseline
    st = render_stereo(teapot, cam, sep, RenderSettings(), threads=2)
    assert st.reuse_ratio >= 0.9
    assert st.holes > 0  # disocclusion behind the teapot and the right frame edge
    assert st.silhouettes > 0  # edges are re-traced: which side a pixel centre falls on differs per eye
    direct = render(teapot, cam.shifted(sep / 2), RenderSettings(), threads=2)
    traced = st.right.aovs["sample_kind"] == 0
    # Traced bad pixels are exactly what a direct render gives (same rays through the same pixels).
    same_obj = st.right.aovs["object_id"] == direct.aovs["object_id"]
    assert np.mean(same_obj) > 0.98
    assert np.mean(same_obj[traced]) > 0.99
    mse = float(np.mean((np.clip(st.right.image, 0, 1) - np.clip(direct.image, 0, 1)) ** 2))
    assert 10 * np.log10(1 / mse) > 30
    c = st.right.counters
    assert c["reprojections"] == 160 * 120 and c["gbuffer_prefetch_bytes"] > 0
    assert c["samples_reused"] + c["samples_traced"] == 160 * 120


def test_disocclusion_is_traced_not_smeared():
    scene = effects_scene()
    cam = effects_camera(120, 68)
    st = render_stereo(scene, cam, 0.4, RenderSettings(max_depth=0), threads=2)
    direct = render(scene, cam.shifted(0.2), RenderSettings(max_depth=0), threads=2)
    wrong = st.right.aovs["object_id"] != direct.aovs["object_id"]
    assert np.mean(wrong) < 0.01


def test_bad_separation_raises(teapot):
    with pytest.raises(ValueError):
        render_stereo(teapot, teapot_camera(16, 16), -0.1, RenderSettings())
    with pytest.raises(ValueError):
        render_stereo(teapot, teapot_camera(16, 16), float("nan"), RenderSettings())


def _wall_scene(distance: float):
    """A large wall facing a camera at the origin looking down +Y: every pixel hits it at `distance`."""
    from sim_core import Scene

    d = distance
    pos = np.array([[-100, d, -100], [100, d, -100], [100, d, 100], [-100, d, 100]], dtype=np.float32)
    return Scene.from_arrays(pos, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64), environment=(0, 0, 0))


def test_gbuffer_prefetch_is_the_reachable_disparity_span():
    """Hand-computed: 64 x 32 px, tan(vfov/2) = 0.5, so the focal length is 32 px; a wall at depth 4 and an
    eye separation of 0.5 give a disparity of 32 * 0.5 / 4 = 4 px. A right-eye tile (16 x 16) reads the left
    columns [x0 + 4, x0 + 20) of its own rows, clamped to the image: 16 + 16 + 16 + 12 columns per band of
    16 rows, two bands, 32 bytes per texel."""
    from sim_core import Camera

    scene = _wall_scene(4.0)
    cam = Camera.look_at((0, 0, 0), (0, 1, 0), (0, 0, 1), 2 * np.arctan(0.5), 64, 32)
    settings = RenderSettings(tile_size=16, max_depth=0, shadow_samples=0)
    st = render_stereo(scene, cam, 0.5, settings, threads=2)
    assert st.right.counters["gbuffer_prefetch_bytes"] == 2 * 16 * (16 + 16 + 16 + 12) * 32  # 61,440
    # Zero separation: every tile reads exactly its own texels, the whole G-buffer once.
    st0 = render_stereo(scene, cam, 0.0, settings, threads=1)
    assert st0.right.counters["gbuffer_prefetch_bytes"] == 64 * 32 * 32
    # A wall at depth 1: disparity 16 px, so the last column of tiles reaches past the image edge (nothing
    # to fetch: all its pixels are holes) and the others read 16 columns each.
    near = render_stereo(_wall_scene(1.0), cam, 0.5, settings, threads=2).right.counters
    assert near["gbuffer_prefetch_bytes"] == 2 * 16 * (16 + 16 + 16 + 0) * 32
