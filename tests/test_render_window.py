"""render_window: a window of the frame traced alone has the frame's pixels and, on the tile grid, its
per-tile counters (what the display-resolution tile estimator relies on)."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from tracer_scenes import effects_camera, effects_scene

import sim_core

RAYS = sim_core.COUNTER_NAMES.index("rays_total")


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


@pytest.mark.parametrize(("mode", "block", "ao"), [
    ("1spp", 2, 0), ("1spp", 2, 2), ("fsaa", 2, 0), ("fsaa", 3, 2), ("undersample", 2, 0),
    ("undersample", 4, 2), ("supersample", 2, 2), ("supersample", 3, 0)])
def test_a_window_off_the_grid_keeps_the_frames_tile_grid(scene, mode, block, ao):
    """A window off the tile grid has the frame's pixels and AOVs in every mode (the adaptive ones too:
    the frame's tile grid is kept inside it); its whole tiles have the frame's counters and histograms, and
    the tiles its edges cut are reported as their parts, traced with fewer rays than the whole tiles."""
    cam = effects_camera(72, 52)
    s = sim_core.RenderSettings(mode=mode, block=block, shadow_samples=2, ao_samples=ao, max_depth=1,
                                tile_size=8)
    full = sim_core.render(scene, cam, s, threads=2)
    by_origin = {(t["x0"], t["y0"]): i for i, t in enumerate(full.tile_stats)}
    for x, y, ww, wh in ((5, 3, 17, 11), (3, 0, 30, 28), (0, 13, 72, 5), (61, 45, 11, 7), (9, 9, 6, 2)):
        part = sim_core.render_window(scene, cam, s, (x, y, ww, wh), threads=2)
        np.testing.assert_array_equal(part.image, full.image[y:y + wh, x:x + ww])
        for name, aov in part.aovs.items():
            np.testing.assert_array_equal(aov, full.aovs[name][y:y + wh, x:x + ww], err_msg=name)
        rects = [(t["x0"], t["y0"], t["width"], t["height"]) for t in part.tile_stats]
        # the frame's grid clipped to the window, row-major
        xs = sorted({x, x + ww} | {v for v in range(0, 72, 8) if x < v < x + ww})
        ys = sorted({y, y + wh} | {v for v in range(0, 52, 8) if y < v < y + wh})
        assert rects == [(x0, y0, x1 - x0, y1 - y0) for y0, y1 in itertools.pairwise(ys)
                         for x0, x1 in itertools.pairwise(xs)]
        size = {(t["x0"], t["y0"]): (t["width"], t["height"]) for t in full.tile_stats}
        whole = [(i, by_origin[r[:2]]) for i, r in enumerate(rects) if size.get(r[:2]) == r[2:]]
        cut = [i for i in range(len(rects)) if i not in {a for a, _ in whole}]
        if whole:
            a, b = (list(v) for v in zip(*whole, strict=True))
            np.testing.assert_array_equal(part.tile_counters[a], full.tile_counters[b])
            np.testing.assert_array_equal(part.tile_histograms[a], full.tile_histograms[b])
        assert cut  # every window here cuts tiles
        frame_rays = {(t["x0"] // 8, t["y0"] // 8): int(full.tile_counters[i, RAYS])
                      for i, t in enumerate(full.tile_stats)}
        for i in cut:
            assert part.tile_counters[i, RAYS] <= frame_rays[(rects[i][0] // 8, rects[i][1] // 8)]
        assert part.counters["rays_total"] == int(part.tile_counters[:, RAYS].sum())
        if (x, y, ww, wh) == (5, 3, 17, 11):
            assert part.counters["rays_total"] < int(full.tile_counters[[
                by_origin[(tx, ty)] for tx in (0, 8, 16) for ty in (0, 8)], RAYS].sum())


def test_a_windows_bounds_are_checked(scene):
    cam = effects_camera(48, 32)
    fsaa = sim_core.RenderSettings(mode="fsaa", shadow_samples=4, tile_size=8)
    with pytest.raises(ValueError, match="inside"):
        sim_core.render_window(scene, cam, fsaa, (40, 0, 16, 8))
    with pytest.raises(ValueError, match="window must be"):
        sim_core.render_window(scene, cam, fsaa, (1, 2))


def _frame_tiles(full, x, y, ww, wh, ring):
    """Rows of ``full``'s tiles inside the window (ring 0) or in the ring of tiles around it (ring 1)."""
    ts = full.settings.tile_size
    rows = []
    for i, t in enumerate(full.tile_stats):
        inside = x <= t["x0"] < x + ww and y <= t["y0"] < y + wh
        near = x - ts <= t["x0"] < x + ww + ts and y - ts <= t["y0"] < y + wh + ts
        if (inside if ring == 0 else near and not inside):
            rows.append(i)
    return rows


@pytest.mark.parametrize(("mode", "block"), [("1spp", 2), ("fsaa", 2), ("fsaa", 3), ("undersample", 2),
                                             ("undersample", 4), ("supersample", 2), ("supersample", 4)])
@pytest.mark.parametrize("tile", [4, 8, 16])
def test_a_windows_apron_is_only_what_its_resolve_reads(scene, mode, block, tile):
    """A window traces only the pixels its pixel filter and ambient pool read around it (adaptively, the
    reference cells holding them), fewer rays than the whole tiles there, and still has the frame's
    pixels, AOVs, per-tile counters and histograms: in the middle, on the frame's edges and corners."""
    cam = effects_camera(72, 52)
    s = sim_core.RenderSettings(mode=mode, block=block, shadow_samples=2, ao_samples=2, max_depth=1,
                                tile_size=tile)
    full = sim_core.render(scene, cam, s, threads=2)
    assert full.counters["ambient_filter_taps"] > 0  # the ambient pool runs
    for x, y, tx, ty in ((tile, tile, 2, 2), (0, 0, 1, 1), (2 * tile, 0, 3, 1), (0, 2 * tile, 99, 99)):
        ww, wh = min(tx * tile, 72 - x), min(ty * tile, 52 - y)
        part = sim_core.render_window(scene, cam, s, (x, y, ww, wh), threads=2)
        np.testing.assert_array_equal(part.image, full.image[y:y + wh, x:x + ww])
        for name, aov in part.aovs.items():
            np.testing.assert_array_equal(aov, full.aovs[name][y:y + wh, x:x + ww], err_msg=name)
        rows = _frame_tiles(full, x, y, ww, wh, 0)
        assert [(t["x0"], t["y0"]) for t in part.tile_stats] == \
            [(full.tile_stats[i]["x0"], full.tile_stats[i]["y0"]) for i in rows]
        np.testing.assert_array_equal(part.tile_counters, full.tile_counters[rows])
        np.testing.assert_array_equal(part.tile_histograms, full.tile_histograms[rows])
        # the whole tiles around the window, as the frame traces them: an upper bound of the apron's rays
        ring = int(full.tile_counters[_frame_tiles(full, x, y, ww, wh, 1), RAYS].sum())
        assert 0 < part.extra["apron_rays"] <= ring
        if tile > sim_core.window_apron(s):
            assert part.extra["apron_rays"] < ring


def test_a_window_without_a_resolve_pass_traces_no_apron(scene):
    cam = effects_camera(48, 32)
    s = sim_core.RenderSettings(mode="undersample", block=3, shadow_samples=2, tile_size=8)
    assert sim_core.window_apron(s) == 0
    assert sim_core.render_window(scene, cam, s, (8, 8, 16, 16)).extra["apron_rays"] == 0
