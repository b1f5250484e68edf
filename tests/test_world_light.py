"""The world's light and the pixel reconstruction, the parts of the model that bring the simulator's max
quality to Cycles' picture (issue 12, bench/bench_fidelity.py): AO rays that see the world unbounded (a
closed room gets none of it), the exact ambient term where nothing blocks the sky, a map's sun as a
light with shadow rays, bilinear environment lookups, and the resolve pass (Cycles' Blackman-Harris pixel
filter, the ambient denoiser), each counted and priced, and none of it paid for by cheap settings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_core import Camera, Material, RenderSettings, Scene, analyze, price, render

FLAT = Material(base_color=(0.8, 0.8, 0.8), roughness=1.0, ior=1.0)  # diffuse only


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box as 12 triangles (both sides shade: the tracer orients normals to the ray)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    p = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], np.float32)
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return p, np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])


def _ground_and_block(**scene_args) -> Scene:
    """A ground (object 0) and a block floating 1..2 m above the origin (object 1): its shadow falls away
    from it."""
    g = 20.0
    ground = np.array([[-g, -g, 0], [g, -g, 0], [g, g, 0], [-g, g, 0]], np.float32)
    bp, bt = _box((-0.5, -0.5, 1.0), (0.5, 0.5, 2.0))
    return Scene.from_arrays(np.vstack([ground, bp]), np.vstack([[[0, 1, 2], [0, 2, 3]], bt + 4]),
                             object_ids=np.r_[0, 0, np.ones(12, int)], materials=[FLAT], **scene_args)


def _sky(sun: float = 0.0, height: int = 64, width: int = 128) -> np.ndarray:
    """A gradient sky over a dark ground, with a 2-texel sun of radiance `sun` at 45 degrees elevation
    towards +X (Blender's mapping: column 3/4 of the width is -Y, 1/2 is +X)."""
    v = (np.arange(height) + 0.5) / height
    sky = np.zeros((height, width, 3), np.float32)
    sky[..., 0] = np.where(v < 0.5, 0.3 + 0.5 * v, 0.1)[:, None]
    sky[..., 1] = np.where(v < 0.5, 0.4 + 0.4 * v, 0.1)[:, None]
    sky[..., 2] = np.where(v < 0.5, 0.9 - 0.3 * v, 0.08)[:, None]
    if sun:
        row, col = height // 4, width // 2
        sky[row - 1:row + 1, col - 1:col + 1] = sun
    return sky


def _look_down(size: int = 32) -> Camera:
    return Camera.look_at((0.0, -0.01, 9.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 0.9, size, size)


def test_a_closed_room_gets_no_world_light() -> None:
    """AO rays see the world unbounded by default: inside a closed box under a white world nothing is lit;
    without AO rays (the cheap setting) the world lights every wall; a short ao_distance lets light in."""
    p, t = _box((-2, -2, -2), (2, 2, 2))
    scene = Scene.from_arrays(p, t, materials=[FLAT], environment=(1.0, 1.0, 1.0))
    cam = Camera.look_at((0, -1.5, 0), (0, 2, 0), (0, 0, 1), 1.0, 24, 24)
    inside = render(scene, cam, RenderSettings(ao_samples=4), threads=2)
    assert inside.image.max() == 0.0
    assert inside.counters["rays_ao"] > 0
    unoccluded = render(scene, cam, RenderSettings(ao_samples=0), threads=2)
    assert unoccluded.image.min() == pytest.approx(0.8, rel=1e-5)
    short = render(scene, cam, RenderSettings(ao_samples=4, ao_distance=0.5), threads=2)
    assert 0.0 < short.image.mean() < 0.8


@pytest.mark.parametrize("world", ["constant", "map"])
def test_an_open_ground_gets_the_exact_ambient_term(world: str) -> None:
    """Where every AO ray is open the visible share is exactly 1: the image equals the unoccluded one (no
    noise from the sampled directions), for a constant world and a map's SH irradiance alike."""
    g = 20.0
    p = np.array([[-g, -g, 0], [g, -g, 0], [g, g, 0], [-g, g, 0]], np.float32)
    env = (0.5, 0.6, 0.7) if world == "constant" else _sky()
    scene = Scene.from_arrays(p, np.array([[0, 1, 2], [0, 2, 3]]), materials=[FLAT], environment=env)
    with_ao = render(scene, _look_down(), RenderSettings(ao_samples=8), threads=2).image
    without = render(scene, _look_down(), RenderSettings(ao_samples=0), threads=2).image
    np.testing.assert_allclose(with_ao, without, rtol=1e-5)


def test_a_maps_sun_is_a_light_with_shadow_rays() -> None:
    """A compact, very bright part of the map lights the scene as a sun light: counted as a light (a shadow
    bit, soft shadows), traced with shadow rays although the scene has no lamp, casting the floating
    block's shadow on the side away from the sun; a map without one has none."""
    lit = _ground_and_block(environment=_sky(sun=3000.0))
    (sun,) = lit.native.environment_lights
    assert np.dot(sun["direction"], (math.sqrt(0.5), 0.0, math.sqrt(0.5))) > math.cos(math.radians(4))
    assert lit.stats["environment_lights"] == 1 and "soft_shadows" in lit.stats["effects"]
    assert analyze(lit).lights == 1 and "rays_shadow" in analyze(lit).possible_counters()
    plain = _ground_and_block(environment=_sky())
    assert plain.native.environment_lights == [] and plain.stats["environment_lights"] == 0
    settings = RenderSettings(shadow_samples=4, ao_samples=8)
    r = render(lit, _look_down(48), settings, threads=2)
    assert r.counters["rays_shadow"] > 0
    assert render(plain, _look_down(48), settings, threads=2).counters["rays_shadow"] == 0
    # The block hangs 1..2 m up at the origin; the sun is 45 degrees up towards +X, so its shadow covers
    # x in (-2, -1) of the ground near y = 0, and the mirror spot x in (1, 2) is in the sun.
    p = r.aovs["position"]
    ground = (r.aovs["object_id"] == 0) & (np.abs(p[..., 1]) < 0.3)
    shadow = r.image[ground & (p[..., 0] > -1.9) & (p[..., 0] < -1.1)].mean()
    sunlit = r.image[ground & (p[..., 0] > 1.1) & (p[..., 0] < 1.9)].mean()
    assert shadow < 0.6 * sunlit


def test_bilinear_environment_lookups_with_filtering_on() -> None:
    """Camera rays read the map between texels when environment filtering is on (four texel reads, priced
    so), the nearest texel when it is off (one)."""
    sky = np.zeros((8, 16, 3), np.float32)
    sky[3:5, 4:6] = 1.0
    far = np.array([[0, 0, -1e3], [1e-3, 0, -1e3], [0, 1e-3, -1e3]], np.float32)
    scene = Scene.from_arrays(far, np.array([[0, 1, 2]]), environment=sky)
    cam = Camera.look_at((0, 0, 0), (0, 1, 0), (0, 0, 1), 1.2, 32, 32)
    nearest = render(scene, cam, RenderSettings(env_filter="off"), threads=1)
    smooth = render(scene, cam, RenderSettings(env_filter="box"), threads=1)
    assert set(np.unique(nearest.image)) <= {0.0, 1.0}
    assert len(np.unique(smooth.image)) > 10
    e_off = price(nearest, "mobile", 30, scene=scene).energy_j["env_filter"]
    e_on = price(smooth, "mobile", 30, scene=scene).energy_j["env_filter"]
    assert nearest.counters["env_lookups"] == smooth.counters["env_lookups"] > 0 and e_on > e_off


def test_the_resolve_pass_is_counted_priced_and_skipped_when_not_needed() -> None:
    """FSAA resolves its sub-samples and the guard ring with the pixel filter; AO rays add the ambient
    denoiser and its records; one sample per pixel without AO needs no resolve pass and pays nothing."""
    scene = _ground_and_block(environment=(0.5, 0.5, 0.5))
    w, h = 40, 24
    cam = Camera.look_at((0, -6, 4), (0, 0, 0.5), (0, 0, 1), 0.8, w, h)
    fsaa = render(scene, cam, RenderSettings(mode="fsaa", block=2), threads=2).counters
    guard = 2  # 1.5 px of Blackman-Harris reaches 2 sub-samples beyond a 2x2 pixel
    assert fsaa["resolve_bytes"] == (2 * w + 2 * guard) * (2 * h + 2 * guard) * 8
    assert fsaa["resolve_taps"] == 6 * w * ((2 * h + 2 * guard) + h)
    assert fsaa["ambient_filter_taps"] == 0
    # The guard ring's samples are traced (and counted) like the frame's own.
    assert fsaa["samples_traced"] == (2 * w + 2 * guard) * (2 * h + 2 * guard)
    one = render(scene, cam, RenderSettings(mode="1spp", ao_samples=0), threads=2)
    assert one.counters["resolve_bytes"] == one.counters["resolve_taps"] == 0
    assert one.counters["ambient_filter_taps"] == 0
    report = price(one, "mobile", 30)
    assert report.energy_j["resolve"] == report.energy_j["resolve_dram"] == 0.0
    ao = render(scene, cam, RenderSettings(mode="1spp", ao_samples=4), threads=2)
    assert ao.counters["resolve_bytes"] == w * h * (8 + 32) and ao.counters["resolve_taps"] == 0
    assert ao.counters["ambient_filter_taps"] > 0
    report = price(ao, "mobile", 30)
    assert report.energy_j["resolve"] > 0 and report.energy_j["resolve_dram"] > 0


def test_the_pixel_filter_keeps_a_flat_frame_flat_to_its_edges() -> None:
    """The guard ring completes every edge pixel's filter: a frame of constant radiance resolves to it
    everywhere, corners included."""
    far = np.array([[0, 0, -1e3], [1e-3, 0, -1e3], [0, 1e-3, -1e3]], np.float32)
    scene = Scene.from_arrays(far, np.array([[0, 1, 2]]), environment=(0.25, 0.5, 0.75))
    cam = Camera.look_at((0, 0, 0), (0, 1, 0), (0, 0, 1), 1.0, 20, 12)
    for block in (2, 3, 4):
        img = render(scene, cam, RenderSettings(mode="fsaa", block=block), threads=2).image
        np.testing.assert_allclose(img, np.broadcast_to([0.25, 0.5, 0.75], img.shape), rtol=1e-5)


def test_ambient_denoiser_smooths_without_darkening() -> None:
    """A floor under a block in a constant world: the denoised AO (4 rays) matches many rays' mean and is
    far less noisy than the rays it pools would be alone."""
    scene = _ground_and_block(environment=(1.0, 1.0, 1.0))
    cam = Camera.look_at((0, -5, 6), (0, 0, 0), (0, 0, 1), 0.9, 48, 48)
    few = render(scene, cam, RenderSettings(mode="fsaa", ao_samples=4), threads=2).image
    many = render(scene, cam, RenderSettings(mode="fsaa", ao_samples=64), threads=2).image
    floor = render(scene, cam, RenderSettings(mode="fsaa", ao_samples=4), threads=2).aovs["object_id"]
    assert few.mean() == pytest.approx(many.mean(), rel=0.02)
    diff = (few - many)[..., 0][floor == 0]
    assert np.sqrt(np.mean(diff ** 2)) < 0.02
