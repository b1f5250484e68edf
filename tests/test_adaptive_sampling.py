"""Adaptive sampling schedules: reference grid, similarity test, multi-rate tiles with hysteresis."""

from __future__ import annotations

import numpy as np
import pytest
from tracer_scenes import effects_camera, effects_scene, teapot_camera, teapot_on_plane

from sim_core import RenderSettings, render


@pytest.fixture(scope="module")
def teapot():
    return teapot_on_plane()


@pytest.mark.parametrize("block", [2, 3, 4])
def test_reference_samples_are_always_traced(teapot, block):
    # With everything similar (180 degrees), a tile traces exactly its reference grid: every `block`-th
    # column/row plus the tile's last column/row.
    cam = teapot_camera(32, 32)
    flat = teapot_on_plane()
    r = render(
        flat,
        cam,
        RenderSettings(
            mode="undersample", block=block, normal_threshold_deg=180.0, tile_size=16, shadow_samples=0
        ),
        threads=2,
    )
    per_axis = len({*range(0, 16, block), 15})
    expected_min = 4 * per_axis * per_axis
    assert r.counters["samples_traced"] >= expected_min
    assert r.counters["samples_traced"] + r.counters["samples_interpolated"] == 32 * 32
    for t in r.tile_stats:
        assert t["block"] == block


def test_coarser_blocks_trace_fewer_samples(teapot):
    cam = teapot_camera(96, 72)
    traced = [
        render(teapot, cam, RenderSettings(mode="undersample", block=b), threads=2).counters["samples_traced"]
        for b in (2, 3, 4)
    ]
    assert traced[0] > traced[1] > traced[2]


def test_stricter_threshold_traces_more(teapot):
    cam = teapot_camera(96, 72)
    loose = render(teapot, cam, RenderSettings(mode="undersample", normal_threshold_deg=45.0), threads=2)
    strict = render(teapot, cam, RenderSettings(mode="undersample", normal_threshold_deg=1.0), threads=2)
    assert strict.counters["samples_traced"] > loose.counters["samples_traced"]
    assert strict.counters["similarity_checks"] > 0
    ratio = [t["similarity_ratio"] for t in loose.tile_stats if t["similarity_checks"]]
    assert all(0.0 <= x <= 1.0 for x in ratio)


def test_secondary_hits_take_part_in_similarity():
    # The same scene with mirrors: at a depth limit of 0 the reflections cannot split similar pixels, so
    # undersampling interpolates more than with one bounce, where the reflected objects must agree too.
    scene = effects_scene()
    cam = effects_camera(96, 54)
    s0 = render(scene, cam, RenderSettings(mode="undersample", max_depth=0), threads=2)
    s1 = render(scene, cam, RenderSettings(mode="undersample", max_depth=1), threads=2)
    assert s1.counters["samples_traced"] > s0.counters["samples_traced"]


def test_supersampling_between_1spp_and_fsaa(teapot):
    cam = teapot_camera(64, 48)
    fsaa = render(teapot, cam, RenderSettings(mode="fsaa", block=2), threads=2)
    ss = render(teapot, cam, RenderSettings(mode="supersample", block=2), threads=2)
    assert cam.width * cam.height < ss.counters["samples_traced"] < fsaa.counters["samples_traced"]
    mse = float(np.mean((ss.image - fsaa.image) ** 2))
    assert 10 * np.log10(1.0 / mse) > 35


def test_multirate_hysteresis_and_explicit_state(teapot):
    cam = teapot_camera(96, 64)
    s = RenderSettings(mode="undersample", block=2, multirate=True, multirate_low=0.5, multirate_high=0.9)
    f0 = render(teapot, cam, s, threads=2)
    assert np.all(f0.multirate_state.block == 2)  # no previous frame: the configured block
    f1 = render(teapot, cam, s, threads=2, previous=f0)
    b0, r0 = f0.multirate_state.block, f0.multirate_state.ratio
    b1 = f1.multirate_state.block
    # Each tile moved by at most one step, in the direction its ratio asked for, or stayed in the band.
    assert np.all(np.abs(b1 - b0) <= 1)
    assert np.all(b1[r0 >= 0.9] == np.minimum(b0[r0 >= 0.9] + 1, 4))
    band = (r0 >= 0.5) & (r0 < 0.9)
    assert np.all(b1[band] == b0[band])
    assert np.all(b1[r0 < 0.5] == np.maximum(b0[r0 < 0.5] - 1, 2))
    assert (b1 > 2).any()
    assert f1.counters["samples_traced"] < f0.counters["samples_traced"]
    # Passing the state object itself is the same as passing the result.
    f1b = render(teapot, cam, s, threads=2, previous=f0.multirate_state)
    np.testing.assert_array_equal(f1.image, f1b.image)
    # A state from a different resolution is ignored (fresh start), never misapplied.
    other = render(teapot, teapot_camera(48, 32), s, threads=2)
    f_other = render(teapot, cam, s, threads=2, previous=other)
    np.testing.assert_array_equal(f_other.image, f0.image)
    # Without multirate the previous state changes nothing.
    plain = RenderSettings(mode="undersample", block=2)
    np.testing.assert_array_equal(
        render(teapot, cam, plain, threads=2, previous=f1).image, render(teapot, cam, plain, threads=2).image
    )


def test_multirate_stays_stable_on_a_static_view(teapot):
    cam = teapot_camera(64, 48)
    s = RenderSettings(mode="undersample", multirate=True)
    prev, blocks = None, []
    for _ in range(5):
        prev = render(teapot, cam, s, threads=2, previous=prev)
        blocks.append(prev.multirate_state.block.copy())
    np.testing.assert_array_equal(blocks[-1], blocks[-2])  # converged: no flip-flopping


def test_previous_must_be_a_state(teapot):
    with pytest.raises(ValueError):
        render(teapot, teapot_camera(16, 16), RenderSettings(), previous="frame 0")
