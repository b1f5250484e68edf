"""render_window: a window of the frame traced alone has the frame's pixels and, on the tile grid, its
per-tile counters (what the display-resolution tile estimator relies on)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tracer_scenes import effects_camera, effects_scene

import sim_core


@pytest.fixture(scope="module")
def scene() -> sim_core.Scene:
    return effects_scene()


@pytest.mark.parametrize("mode", ["fsaa", "undersample", "supersample", "1spp"])
@pytest.mark.parametrize("scale", [1.0, 0.7])
def test_window_on_the_tile_grid_traces_the_frames_tiles(scene, mode, scale):
    cam = effects_camera(70, 44)
    s = sim_core.RenderSettings(mode=mode, block=2, shadow_samples=4, ao_samples=2, max_depth=2,
                                resolution_scale=scale, tile_size=8)
    full = sim_core.render(scene, cam, s, threads=2)
    w, h = sim_core.render_size(cam, s)
    assert (w, h) == full.render_resolution
    x, y = 8, 16
    ww, wh = w - x, min(16, h - y)  # reaches the right edge; two tile rows
    part = sim_core.render_window(scene, cam, s, (x, y, ww, wh), threads=2)
    traced = sim_core.render(scene, cam.with_resolution(w, h), dataclasses.replace(s, resolution_scale=1.0))
    np.testing.assert_array_equal(part.image, traced.image[y:y + wh, x:x + ww])
    by_origin = {(t["x0"], t["y0"]): i for i, t in enumerate(full.tile_stats)}
    rows = [by_origin[(t["x0"], t["y0"])] for t in part.tile_stats]
    np.testing.assert_array_equal(part.tile_counters, full.tile_counters[rows])
    np.testing.assert_array_equal(part.tile_histograms, full.tile_histograms[rows])
    assert part.counters["rays_total"] == int(full.tile_counters[rows, 6].sum())


def test_window_off_the_grid(scene):
    cam = effects_camera(48, 32)
    fsaa = sim_core.RenderSettings(mode="fsaa", shadow_samples=4, tile_size=8)
    full = sim_core.render(scene, cam, fsaa)
    part = sim_core.render_window(scene, cam, fsaa, (5, 3, 17, 11))
    np.testing.assert_array_equal(part.image, full.image[3:14, 5:22])
    with pytest.raises(ValueError, match="tile grid"):
        sim_core.render_window(scene, cam, sim_core.RenderSettings(mode="undersample", tile_size=8),
                               (5, 3, 17, 11))
    with pytest.raises(ValueError, match="inside"):
        sim_core.render_window(scene, cam, fsaa, (40, 0, 16, 8))
    with pytest.raises(ValueError, match="window must be"):
        sim_core.render_window(scene, cam, fsaa, (1, 2))
