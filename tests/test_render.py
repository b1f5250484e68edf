"""Renderer: determinism, exactness of the adaptive modes at full rate, shading effects, counters, acne."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tracer_scenes import effects_camera, effects_scene, sky_map, teapot_camera, teapot_on_plane

import sim_core
from sim_core import COUNTER_NAMES, Camera, Light, Material, RenderSettings, Scene, render


@pytest.fixture(scope="module")
def teapot():
    return teapot_on_plane()


@pytest.fixture(scope="module")
def effects():
    return effects_scene()


def test_image_and_aovs_shapes(teapot):
    cam = teapot_camera(96, 64)
    r = render(teapot, cam, RenderSettings(), threads=2)
    assert r.image.shape == (64, 96, 3) and r.image.dtype == np.float32
    assert np.all(np.isfinite(r.image)) and r.image.min() >= 0
    assert r.aovs["depth"].shape == (64, 96) and r.aovs["normal"].shape == (64, 96, 3)
    assert set(np.unique(r.aovs["object_id"])) <= {-1, 0, 1}
    assert np.all(r.aovs["sample_kind"] == 0)
    assert set(r.counters) == set(COUNTER_NAMES)
    c = r.counters
    assert c["pixels"] == 96 * 64 == c["rays_primary"] == c["raygen_evals"] == c["samples_traced"]
    assert c["rays_total"] == sum(
        c[k]
        for k in (
            "rays_primary",
            "rays_shadow",
            "rays_reflection",
            "rays_refraction",
            "rays_ao",
            "rays_glossy",
        )
    )
    assert c["framebuffer_bytes"] == 4 * 96 * 64
    assert c["cache_accesses"] >= c["cache_misses"] > 0 and c["dram_bytes_read"] == 64 * c["cache_misses"]
    assert (
        r.comparator_histogram.shape == (25,) and r.comparator_histogram.sum() == c["closest_hit_comparisons"]
    )
    assert len(r.tile_stats) == 6 * 4
    assert sum(t["samples_traced"] for t in r.tile_stats) == c["samples_traced"]
    # Hits: finite depth and unit normals; misses: inf depth, object -1.
    hit = r.aovs["object_id"] >= 0
    assert hit.any() and (~hit).any()
    assert np.all(np.isfinite(r.aovs["depth"][hit])) and np.all(np.isinf(r.aovs["depth"][~hit]))
    np.testing.assert_allclose(np.linalg.norm(r.aovs["normal"][hit], axis=-1), 1.0, atol=1e-4)


@pytest.mark.parametrize("mode", ["fsaa", "undersample"])
def test_tile_counters_add_up_to_the_frame(effects, mode):
    """Every tile's own counters and comparator histogram (cold caches per tile) sum to the frame's, and
    each row is the tile's: a sample of tiles prices a sample of the frame."""
    cam = effects_camera(72, 40)
    r = render(effects, cam, RenderSettings(mode=mode, block=2, shadow_samples=4, max_depth=2), threads=2)
    tc, th = r.tile_counters, r.tile_histograms
    assert tc.shape == (len(r.tile_stats), len(COUNTER_NAMES)) and tc.dtype == np.uint64
    assert th.shape == (len(r.tile_stats), 25)
    for i, name in enumerate(COUNTER_NAMES):
        assert int(tc[:, i].sum()) == r.counters[name], name
    np.testing.assert_array_equal(th.sum(axis=0), r.comparator_histogram)
    col = {n: i for i, n in enumerate(COUNTER_NAMES)}
    for row, t in zip(tc, r.tile_stats, strict=True):
        assert row[col["pixels"]] == t["width"] * t["height"]
        assert row[col["rays_total"]] == t["rays_total"] and row[col["cache_misses"]] == t["cache_misses"]


@pytest.mark.parametrize("mode", ["1spp", "fsaa", "undersample", "supersample"])
def test_same_image_for_one_and_two_threads(effects, mode):
    cam = effects_camera(80, 48)
    s = RenderSettings(mode=mode, block=2, shadow_samples=4, ao_samples=2, max_depth=3)
    a = render(effects, cam, s, threads=1)
    b = render(effects, cam, s, threads=2)
    np.testing.assert_array_equal(a.image, b.image)
    assert a.counters == b.counters
    np.testing.assert_array_equal(a.comparator_histogram, b.comparator_histogram)


@pytest.mark.parametrize("block", [2, 3, 4])
def test_undersampling_with_nothing_similar_equals_1spp(effects, block):
    cam = effects_camera(72, 40)
    base = dict(shadow_samples=4, ao_samples=2, max_depth=2, tile_size=16)
    ref = render(effects, cam, RenderSettings(mode="1spp", **base), threads=2)
    r = render(
        effects,
        cam,
        RenderSettings(mode="undersample", block=block, normal_threshold_deg=-1.0, **base),
        threads=2,
    )
    np.testing.assert_array_equal(r.image, ref.image)
    np.testing.assert_array_equal(r.aovs["depth"], ref.aovs["depth"])
    assert r.counters["samples_interpolated"] == 0 and r.counters["similarity_checks"] > 0
    assert r.counters["rays_total"] == ref.counters["rays_total"]


def test_supersampling_with_nothing_similar_equals_fsaa(effects):
    cam = effects_camera(48, 32)
    ref = render(effects, cam, RenderSettings(mode="fsaa", block=3), threads=2)
    r = render(
        effects, cam, RenderSettings(mode="supersample", block=3, normal_threshold_deg=-5.0), threads=2
    )
    np.testing.assert_array_equal(r.image, ref.image)


def test_undersampling_traces_fewer_rays_and_stays_close(teapot):
    cam = teapot_camera(160, 120)
    ref = render(teapot, cam, RenderSettings(), threads=2)
    r = render(teapot, cam, RenderSettings(mode="undersample", block=2), threads=2)
    assert r.counters["samples_traced"] <= 0.5 * ref.counters["samples_traced"]
    assert r.counters["samples_traced"] + r.counters["samples_interpolated"] == ref.counters["pixels"]
    mse = float(np.mean((np.clip(r.image, 0, 1) - np.clip(ref.image, 0, 1)) ** 2))
    assert 10 * math.log10(1 / mse) > 35
    kinds = np.bincount(r.aovs["sample_kind"].ravel(), minlength=3)
    assert kinds[1] == r.counters["samples_interpolated"] and kinds[2] == 0


def test_effects_counters_and_model_only_what_is_needed(effects, teapot):
    cam = effects_camera(64, 36)
    r = render(effects, cam, RenderSettings(max_depth=2, shadow_samples=4, ao_samples=3), threads=2)
    c = r.counters
    for k in ("rays_reflection", "rays_refraction", "rays_glossy", "rays_ao", "rays_shadow"):
        assert c[k] > 0, k
    # A constant-colour environment needs no lookup: rays leave the scene, yet nothing is counted.
    assert c["env_lookups"] == 0 and c["env_filtered_lookups"] == 0
    # Depth 0: no secondary rays at all; no AO samples: no AO rays; no shadows: no shadow rays.
    r0 = render(effects, cam, RenderSettings(max_depth=0, shadow_samples=0, ao_samples=0), threads=2)
    for k in ("rays_reflection", "rays_refraction", "rays_glossy", "rays_ao", "rays_shadow"):
        assert r0.counters[k] == 0, k
    # The diffuse teapot scene has no refraction and no mirrors: those counters stay 0 at any depth.
    diffuse = teapot_on_plane(roughness=0.9)
    rt = render(diffuse, teapot_camera(48, 32), RenderSettings(max_depth=4), threads=2)
    assert rt.counters["rays_refraction"] == 0 and rt.counters["rays_reflection"] == 0
    assert rt.counters["rays_glossy"] == 0 and rt.counters["env_filtered_lookups"] == 0
    # Hard shadows from a light with radius: N soft samples cost N rays per lit hit.
    r4 = render(teapot, teapot_camera(48, 32), RenderSettings(shadow_samples=4), threads=2)
    r1 = render(teapot, teapot_camera(48, 32), RenderSettings(shadow_samples=1), threads=2)
    assert r4.counters["rays_shadow"] == 4 * r1.counters["rays_shadow"]


def test_mirror_reflects_what_is_in_front():
    # A mirror floor under a red emissive box seen from above at an angle: the floor shows red.
    floor = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], np.float32)
    box = np.array([[-1, 2, 0.5], [1, 2, 0.5], [1, 2, 2.5], [-1, 2, 2.5]], np.float32)
    pos = np.vstack([floor, box])
    tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    mats = [
        Material(base_color=(1, 1, 1), metallic=1.0, roughness=0.0),
        Material(base_color=(0, 0, 0), emission=(1.0, 0.0, 0.0)),
    ]
    scene = Scene.from_arrays(
        pos, tri, material_ids=[0, 0, 1, 1], object_ids=[0, 0, 1, 1], materials=mats, environment=(0, 0, 0)
    )
    cam = Camera.look_at((0, -4, 2), (0, 2, 0), (0, 0, 1), 0.9, 64, 48)
    r = render(scene, cam, RenderSettings(max_depth=1), threads=2)
    floor_px = r.aovs["object_id"] == 0
    refl = r.image[floor_px]
    assert np.max(refl[:, 0]) > 0.9 and np.all(refl[:, 1:] < 1e-6)
    r0 = render(scene, cam, RenderSettings(max_depth=0), threads=2)
    assert np.max(r0.image[r0.aovs["object_id"] == 0][:, 0]) < 1e-6


def test_glass_refracts_and_conserves():
    # A glass slab in front of a green backdrop: seen through, the backdrop stays green and bright.
    slab = np.array([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]], np.float32)
    back = np.array([[-9, 5, -9], [9, 5, -9], [9, 5, 9], [-9, 5, 9]], np.float32)
    slab2 = slab + np.array([0, 0.3, 0], np.float32)
    pos = np.vstack([slab, slab2, back])
    tri = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [8, 9, 10], [8, 10, 11]])
    mats = [
        Material(base_color=(1, 1, 1), transmission=1.0, ior=1.5, roughness=0.0),
        Material(base_color=(0, 0, 0), emission=(0, 1, 0)),
    ]
    scene = Scene.from_arrays(
        pos,
        tri,
        material_ids=[0, 0, 0, 0, 1, 1],
        object_ids=[0, 0, 0, 0, 1, 1],
        materials=mats,
        environment=(0, 0, 0),
    )
    cam = Camera.look_at((0, -5, 0), (0, 0, 0), (0, 0, 1), 0.4, 32, 32)
    r = render(scene, cam, RenderSettings(max_depth=4), threads=2)
    centre = r.image[16, 16]
    assert r.counters["rays_refraction"] > 0
    # Two interfaces at normal incidence each reflect 4 %: about 0.96^2 of the green gets through.
    assert centre[1] == pytest.approx(0.96**2, abs=0.03) and centre[0] < 1e-6


@pytest.mark.parametrize("env_filter", ["off", "box", "bartlett"])
def test_environment_map_and_glossy_filter(env_filter):
    sky = sky_map()
    scene = effects_scene(environment=sky)
    cam = effects_camera(48, 32)
    r = render(scene, cam, RenderSettings(env_filter=env_filter, max_depth=1), threads=2)
    assert np.all(np.isfinite(r.image))
    assert r.counters["env_lookups"] > 0  # primary and mirror rays that miss read the map
    if env_filter == "off":
        assert r.counters["env_filtered_lookups"] == 0 and r.counters["rays_glossy"] > 0
    else:
        assert r.counters["env_filtered_lookups"] > 0
    # The top rows see the sky map's upper part (bluish), not a constant.
    assert r.image[0].std(axis=0).sum() >= 0 and r.image[0, :, 2].mean() > r.image[0, :, 0].mean()


def test_resolution_scale_renders_fewer_pixels(teapot):
    cam = teapot_camera(100, 60)
    r = render(teapot, cam, RenderSettings(resolution_scale=0.5), threads=2)
    assert r.image.shape == (60, 100, 3)
    assert r.render_resolution == (50, 30) and r.counters["pixels"] == 1500
    assert r.aovs["depth"].shape == (30, 50)


def _plane_scene(scale: float, offset: tuple[float, float, float], seed: int = 0):
    """A tilted, finely triangulated lit plane: nothing can shadow it, so any occluded shadow ray is acne."""
    rng = np.random.default_rng(seed)
    n = 24
    g = np.linspace(-1, 1, n + 1)
    gx, gy = np.meshgrid(g, g)
    jitter = rng.uniform(-0.3, 0.3, size=(2, *gx.shape)) * (2 / n)
    jitter[:, [0, -1], :] = 0
    jitter[:, :, [0, -1]] = 0
    p = np.stack([gx + jitter[0], gy + jitter[1], np.zeros_like(gx)], -1).reshape(-1, 3)
    tris = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            tris += [(a, a + 1, a + n + 2), (a, a + n + 2, a + n + 1)]
    # Tilt about X and Z so no coordinate is constant over the plane.
    ax, az = 0.35, 0.6
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    rot = rz @ rx
    o = np.asarray(offset, np.float64)
    pos = (p @ rot.T) * scale * 10 + o
    normal = rot @ np.array([0, 0, 1.0])
    light_pos = o + scale * (rot @ np.array([3.0, 2.0, 4.0]))
    lights = [
        Light(kind="point", position=tuple(light_pos), intensity=30.0 * scale**2),
        Light(kind="sun", direction=tuple(-(rot @ np.array([0.2, -0.9, 0.4]))), intensity=1.0),
    ]
    scene = Scene.from_arrays(pos.astype(np.float32), np.asarray(tris), lights=lights, environment=(0, 0, 0))
    eye = o + scale * (rot @ np.array([0.0, -14.0, 9.0]))
    cam = Camera.look_at(tuple(eye), tuple(o), tuple(normal), 0.9, 96, 96)
    return scene, cam


@pytest.mark.parametrize(
    ("scale", "offset"),
    [(1e-3, (0.0, 0.0, 0.0)), (1.0, (0.0, 0.0, 0.0)), (1e3, (0.0, 0.0, 0.0)), (1.0, (1e5, -1e5, 1e5))],
)
def test_no_shadow_acne_at_any_scale(scale, offset):
    scene, cam = _plane_scene(scale, offset)
    lit = render(scene, cam, RenderSettings(shadow_samples=1, max_depth=0), threads=2)
    unshadowed = render(scene, cam, RenderSettings(shadow_samples=0, max_depth=0), threads=2)
    on_plane = lit.aovs["object_id"] >= 0
    assert on_plane.mean() > 0.5  # the plane fills the view
    shadow_rays = lit.counters["rays_shadow"]
    assert shadow_rays >= on_plane.sum()  # every lit pixel cast its shadow rays
    false_occlusion = np.count_nonzero(np.any(lit.image != unshadowed.image, axis=-1))
    assert false_occlusion / shadow_rays < 1e-4, f"{false_occlusion} of {shadow_rays} shadow rays self-hit"


def test_camera_from_blender_matches_look_at():
    cam = Camera.look_at((1.0, -6.0, 2.5), (0.0, 0.0, 0.5), (0.0, 0.0, 1.0), 0.8, 40, 30)
    m = cam.matrix_world()
    again = Camera.from_blender(m, 0.8, 40, 30)
    np.testing.assert_allclose(again.forward, cam.forward, atol=1e-12)
    np.testing.assert_allclose(again.up, cam.up, atol=1e-12)
    # Blender's default camera-like matrix: identity rotation looks down -Z.
    c = Camera.from_blender(np.eye(4), 0.6, 10, 10)
    assert c.forward == (0.0, 0.0, -1.0) and c.up == (0.0, 1.0, 0.0)
    o, d = cam.primary_rays()
    assert o.shape == (1200, 3)
    np.testing.assert_allclose(d[15 * 40 + 20] @ np.asarray(cam.forward), 1.0, atol=1e-2)


def test_render_uses_camera_convention(teapot):
    # A camera looking at the teapot from the front sees it in the image centre, right side up:
    # the spout (+X in the Z-up teapot) appears on the right half of the image.
    cam = Camera.look_at((0.0, -9.0, 1.5), (0.0, 0.0, 1.5), (0.0, 0.0, 1.0), 0.6, 80, 60)
    r = render(teapot, cam, RenderSettings(max_depth=0), threads=2)
    teapot_px = r.aovs["object_id"] == 0
    ys, _xs = np.nonzero(teapot_px)
    assert abs(ys.mean() - 30) < 10 and teapot_px[:, 60:].sum() > teapot_px[:, :20].sum()
    ground = r.aovs["object_id"] == 1
    assert ground[-1].mean() > 0.9 and not ground[0].any()  # ground at the bottom, not at the top


@pytest.mark.parametrize(
    "kwargs",
    [
        {"mode": "2spp"},
        {"block": 1},
        {"block": 5},
        {"max_depth": 5},
        {"max_depth": -1},
        {"shadow_samples": -1},
        {"resolution_scale": 0.2},
        {"resolution_scale": 1.5},
        {"resolution_scale": math.nan},
        {"env_filter": "gauss"},
        {"ao_samples": -2},
        {"multirate_low": 0.9, "multirate_high": 0.5},
        {"tile_size": 2},
        {"block": 2.0},
        {"normal_threshold_deg": math.inf},
        {"multirate": 1},
        {"max_depth": True},
    ],
)
def test_settings_validation(kwargs):
    with pytest.raises(ValueError):
        RenderSettings(**kwargs)


def test_settings_max_quality_and_frozen():
    s = RenderSettings.max_quality()
    assert s.mode == "fsaa" and s.resolution_scale == 1.0 and s.shadow_samples >= 16
    with pytest.raises(AttributeError):
        s.block = 3  # type: ignore[misc]
    assert s.replace(block=3).block == 3


def test_render_rejects_bad_arguments(teapot):
    cam = teapot_camera(16, 16)
    with pytest.raises(ValueError):
        render(teapot, cam, RenderSettings(), threads=0)
    with pytest.raises(ValueError):
        render(teapot, "camera", RenderSettings())  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        render(teapot, cam, RenderSettings(), cache=(1000, 64, 4))  # not a power of two
    with pytest.raises(ValueError):
        Camera.look_at((0, 0, 0), (0, 0, 0), (0, 0, 1), 0.5, 10, 10)
    with pytest.raises(ValueError):
        Camera.look_at((0, -1, 0), (0, 0, 0), (0, 0, 1), 0.5, 0, 10)
    with pytest.raises(ValueError):
        Camera.from_blender(np.full((4, 4), np.nan), 0.5, 10, 10)


def test_cache_configuration_changes_misses_not_image(teapot):
    cam = teapot_camera(48, 32)
    small = render(teapot, cam, RenderSettings(), threads=2, cache=(4096, 64, 2))
    big = render(
        teapot, cam, RenderSettings(), threads=2, cache={"size_bytes": 262144, "line_bytes": 64, "ways": 8}
    )
    off = render(teapot, cam, RenderSettings(), threads=2, cache=(0, 64, 4))
    np.testing.assert_array_equal(small.image, big.image)
    assert small.counters["cache_misses"] > big.counters["cache_misses"]
    assert off.counters["cache_misses"] == off.counters["bvh_node_visits"] + off.counters["triangle_tests"]


def test_native_scene_errors_are_value_errors():
    with pytest.raises(ValueError):
        sim_core.Scene.from_arrays(np.zeros((3, 3)), np.array([[0, 1, 2]]))
