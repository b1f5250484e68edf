"""render_tiled: a frame traced band by band (a window of the full frame per native call) is the frame
render() gives, pixel for pixel and counter for counter; camera windows are validated."""

from __future__ import annotations

import numpy as np
import pytest

import sim_core
from sim_core import _core
from tests.api_support import look_at_matrix, teapot_scene_glb


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> sim_core.Scene:
    path = tmp_path_factory.mktemp("scene") / "teapot.glb"
    path.write_bytes(teapot_scene_glb())
    return sim_core.Scene.from_gltf(str(path))


def camera(width: int = 120, height: int = 90) -> sim_core.Camera:
    return sim_core.Camera.from_blender(np.array(look_at_matrix((0.4, -3.0, 1.5), (0, 0, 0.4))), 0.69,
                                        width, height)


@pytest.mark.parametrize("settings", [
    sim_core.RenderSettings(mode="1spp"),
    sim_core.RenderSettings(mode="undersample", block=4, shadow_samples=4),  # adaptive: similarity tests
    sim_core.RenderSettings(mode="fsaa", block=2, ao_samples=2),  # random sampling seeds per sub-sample
    sim_core.RenderSettings(mode="undersample", block=3, resolution_scale=0.5, tile_size=8),
], ids=["1spp", "undersample", "fsaa-ao", "scaled"])
def test_tiled_frame_equals_the_whole_frame(scene: sim_core.Scene, settings: sim_core.RenderSettings) -> None:
    cam = camera()
    whole = sim_core.render(scene, cam, settings)
    seen: list[tuple[int, int]] = []
    tiled = sim_core.render_tiled(scene, cam, settings, band_pixels=1500,
                                  progress=lambda done, total: seen.append((done, total)))
    assert np.array_equal(whole.image, tiled.image)
    assert whole.counters == tiled.counters
    assert np.array_equal(whole.comparator_histogram, tiled.comparator_histogram)
    assert np.array_equal(whole.tile_counters, tiled.tile_counters)  # tiles in the same (row-major) order
    assert np.array_equal(whole.tile_histograms, tiled.tile_histograms)
    for name, aov in whole.aovs.items():
        assert np.array_equal(aov, tiled.aovs[name]), name
    assert sorted((t["x0"], t["y0"], t["width"], t["height"]) for t in whole.tile_stats) == \
        sorted((t["x0"], t["y0"], t["width"], t["height"]) for t in tiled.tile_stats)
    h = tiled.render_resolution[1]
    assert len(seen) > 1 and seen[-1] == (h, h) and [d for d, _ in seen] == sorted({d for d, _ in seen})
    assert tiled.multirate_state is None


def test_tiled_textured_frame_equals_the_whole_frame() -> None:
    """Texture fetches (mip level by ray cone, the texture cache model) are the same band by band."""
    n = 64
    cells = (np.add.outer(np.arange(n) // 4, np.arange(n) // 4) % 2).astype(np.uint8) * 255
    tex = sim_core.Texture(np.stack([cells, cells // 2, np.full_like(cells, 40)], axis=2))
    pos = np.array([[-4, -4, 0], [4, -4, 0], [4, 4, 0], [-4, 4, 0]], dtype=np.float32)
    tri = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    uv = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], dtype=np.float32)
    scene = sim_core.Scene.from_arrays(pos, tri, uvs=uv, textures=[tex],
                                       materials=[sim_core.Material(base_color_texture=0, roughness=0.6)],
                                       lights=[sim_core.Light(kind="sun", direction=(0.3, 0.2, -1.0))])
    cam = sim_core.Camera.look_at((0.5, -5.0, 2.0), (0.0, 0.0, 0.0), (0, 0, 1), 0.8, 96, 64)
    settings = sim_core.RenderSettings(mode="undersample", block=2)
    whole = sim_core.render(scene, cam, settings)
    tiled = sim_core.render_tiled(scene, cam, settings, band_pixels=1000)
    assert whole.counters["texture_fetches"] > 0
    assert np.array_equal(whole.image, tiled.image) and whole.counters == tiled.counters


def test_windows_in_both_directions_sum_to_the_whole_frame(scene: sim_core.Scene) -> None:
    """Windows on the tile grid that read their neighbours' samples in the resolve pass (pixel filter of
    supersampling, ambient denoiser) trace an uncounted apron: pixels and counters add up to the frame."""
    cam = camera(96, 72)
    settings = sim_core.RenderSettings(mode="supersample", block=2, ao_samples=2, tile_size=16)
    whole = sim_core.render(scene, cam, settings, threads=1)
    assert whole.counters["ambient_filter_taps"] > 0 and whole.counters["resolve_taps"] > 0
    image = np.zeros_like(whole.image)
    counters: dict[str, int] = {}
    native = settings.to_native()
    for y0, y1 in ((0, 16), (16, 48), (48, 72)):
        for x0, x1 in ((0, 32), (32, 96)):
            d = _core.render_frame(scene.native, cam.frame(), cam.vfov, x1 - x0, y1 - y0, native, 1, None,
                                   32768, 64, 4, 16384, 64, 4, crop_x=x0, crop_y=y0,
                                   full_width=96, full_height=72)
            image[y0:y1, x0:x1] = d["image"]
            for k, v in d["counters"].items():
                counters[k] = counters.get(k, 0) + int(v)
    assert np.array_equal(whole.image, image)
    assert counters == whole.counters


def test_progress_callback_can_stop_a_render(scene: sim_core.Scene) -> None:
    class Stop(Exception):
        pass

    def stop(done: int, total: int) -> None:
        raise Stop

    with pytest.raises(Stop):
        sim_core.render_tiled(scene, camera(), band_pixels=1000, progress=stop)


@pytest.mark.parametrize("crop", [(0, 80, 120, 90), (-1, 0, 120, 90), (10, 0, 100, 90), (0, 0, 20000, 90)])
def test_camera_windows_outside_their_frame_are_rejected(scene: sim_core.Scene, crop) -> None:
    cam = camera()
    x, y, fw, fh = crop
    with pytest.raises(ValueError, match="window"):
        _core.render_frame(scene.native, cam.frame(), cam.vfov, 120, 20,
                           sim_core.RenderSettings().to_native(), 1, None, 32768, 64, 4, 16384, 64, 4,
                           crop_x=x, crop_y=y, full_width=fw, full_height=fh)
