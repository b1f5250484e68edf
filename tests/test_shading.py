"""Shading features through the Python API: textures (validation, sampling against numpy, rendering,
sharing, counters and their price), area lights and Blender light data, rough and tinted metal
reflections, the world (strength, rotation, clamped HDRI texels, Blender's bundled HDRIs)."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from sim_core.image import srgb_to_linear

import sim_core
from sim_core import Camera, Light, Material, RenderSettings, Scene, Texture, price, render

NEW_COUNTERS = ("rays_alpha", "alpha_tests", "area_light_evals", "texture_fetches", "texel_reads",
                "texture_cache_misses", "texture_dram_bytes", "env_sh_evals")


def _quad(size: float = 2.0, z: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    h = size / 2
    pos = np.array([[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]], np.float32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    return pos, np.array([[0, 1, 2], [0, 2, 3]]), uv


def _top_camera(size: int = 32, height: float = 3.0, fov: float = 0.7) -> Camera:
    return Camera.look_at((0.0, 0.0, height), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov, size, size)


SUN = Light(kind="sun", direction=(0.0, 0.0, -1.0), intensity=math.pi)  # a white diffuse surface shows 1.0
FLAT = Material(base_color=(1.0, 1.0, 1.0), roughness=1.0, ior=1.0)  # diffuse only


# ---- textures ------------------------------------------------------------------------------------


def test_texture_validation() -> None:
    grey = Texture(np.full((4, 4), 128, np.uint8))
    assert grey.rgba().shape == (4, 4, 4) and np.all(grey.rgba()[..., 3] == 255)
    ga = Texture(np.zeros((2, 3, 2), np.uint8), colorspace="linear", wrap_u="clamp", wrap_v="mirror")
    assert ga.rgba().shape == (2, 3, 4) and (ga.width, ga.height) == (3, 2)
    with pytest.warns(UserWarning, match="clamped 1 value.*1 non-finite"):
        f = Texture(np.array([[[np.nan, -1.0, 0.5]]], np.float32))
    assert np.array_equal(f.rgba(), [[[0.0, 0.0, 0.5, 1.0]]])
    for bad, match in [
        (dict(image=np.zeros((2, 2, 5), np.uint8)), "image must be"),
        (dict(image=np.zeros((2, 2, 3), np.int32)), "dtype"),
        (dict(image=np.zeros((0, 2, 3), np.uint8)), "size"),
        (dict(image=np.zeros((2, 2, 3), np.uint8), wrap_u="tile"), "wrap_u"),
        (dict(image=np.zeros((2, 2, 3), np.uint8), colorspace="aces"), "colorspace"),
    ]:
        with pytest.raises(ValueError, match=match):
            Texture(**bad)
    with pytest.raises(ValueError, match="texture index"):
        Material(base_color_texture=-1)
    pos, tri, uv = _quad()
    with pytest.raises(ValueError, match="uses texture 1 but the scene has 1"):
        Scene.from_arrays(pos, tri, uvs=uv, textures=[grey], materials=[Material(base_color_texture=1)])
    with pytest.raises(ValueError, match="uvs must have one row per vertex"):
        Scene.from_arrays(pos, tri, uvs=uv[:3])
    with pytest.raises(ValueError, match="uvs must be finite"):
        Scene.from_arrays(pos, tri, uvs=np.full((4, 2), np.inf))


def test_native_texture_matches_numpy_bilinear_mips_and_srgb() -> None:
    rng = np.random.default_rng(3)
    img = rng.random((8, 16, 4)).astype(np.float32)
    tex = sim_core._core.NativeTexture.from_rgba32f(img, 1, 1)  # clamp, clamp
    assert (tex.width, tex.height, tex.levels, tex.texel_bytes) == (16, 8, 5, 16)

    def bilinear(level_img: np.ndarray, u: float, v: float) -> np.ndarray:
        h, w = level_img.shape[:2]
        x, y = u * w - 0.5, (1 - v) * h - 0.5
        x0, y0 = math.floor(x), math.floor(y)
        fx, fy = x - x0, y - y0

        def t(xi: int, yi: int) -> np.ndarray:
            return level_img[min(max(yi, 0), h - 1), min(max(xi, 0), w - 1)]

        top = (1 - fx) * t(x0, y0) + fx * t(x0 + 1, y0)
        bottom = (1 - fx) * t(x0, y0 + 1) + fx * t(x0 + 1, y0 + 1)
        return (1 - fy) * top + fy * bottom

    level1 = img.reshape(4, 2, 8, 2, 4).mean(axis=(1, 3))  # the 2x2 box pyramid
    for u, v in [(0.1, 0.2), (0.37, 0.81), (0.93, 0.5)]:
        *rgba, taps = tex.sample(u, v, 0.0)
        assert taps == 4 and np.allclose(rgba, bilinear(img, u, v), atol=1e-5)
        *rgba1, _ = tex.sample(u, v, 1.0)
        assert np.allclose(rgba1, bilinear(level1, u, v), atol=1e-5)
        *tri, taps = tex.sample(u, v, 0.5)
        assert taps == 8 and np.allclose(tri, 0.5 * (bilinear(img, u, v) + bilinear(level1, u, v)), atol=1e-5)
    assert np.allclose(tex.texel(4, 0, 0), img.reshape(-1, 4).mean(axis=0), atol=1e-5)
    # sRGB bytes decode with the standard curve before filtering.
    b = np.arange(256, dtype=np.uint8)
    row = np.stack([b, b, b, np.full(256, 255, np.uint8)], axis=1)[None]
    srgb = sim_core._core.NativeTexture.from_rgba8(np.ascontiguousarray(row), True, 1, 1)
    c = b / 255.0
    expected = srgb_to_linear(c)
    got = [srgb.texel(0, i, 0)[0] for i in range(256)]
    assert np.allclose(got, expected, atol=2e-7)


def _checker(n: int = 8) -> Texture:
    cells = (np.add.outer(np.arange(n), np.arange(n)) % 2).astype(np.uint8) * 255
    return Texture(np.stack([cells, cells // 2, np.full_like(cells, 40)], axis=2), name="checker")


def test_textured_quad_renders_its_texels_and_counts_fetches() -> None:
    pos, tri, uv = _quad()
    tex = _checker(4)
    scene = Scene.from_arrays(pos, tri, uvs=uv, textures=[tex], materials=[
        Material(base_color=(1, 1, 1), roughness=1.0, ior=1.0, base_color_texture=0)], lights=[SUN],
        environment=(0, 0, 0))
    assert "textures" in scene.stats["effects"] and scene.textures == [tex]
    # The quad fills a 4x4 image exactly: each pixel centre is a texel centre (one texel per pixel: level 0).
    cam = _top_camera(4, height=2.0, fov=2 * math.atan(0.5))
    r = render(scene, cam, RenderSettings(shadow_samples=0, max_depth=0), threads=2)
    c = tex.image / 255.0
    expected = srgb_to_linear(c)  # sRGB bytes, decoded
    assert np.allclose(r.image, expected, atol=2e-4)
    cnt = r.counters
    assert cnt["texture_fetches"] == cnt["shading_evals"] == 16
    assert cnt["texel_reads"] >= 4 * cnt["texture_fetches"]
    assert cnt["texture_dram_bytes"] == 64 * cnt["texture_cache_misses"] > 0
    report = price(r, "mobile", 30)
    assert report.energy_j["texture"] > 0 and report.energy_j["texture_dram"] > 0


def test_scene_without_new_features_costs_what_it_did() -> None:
    """No textures, area lights or cut-outs: every new counter is 0 and pricing ignores the new blocks."""
    pos, tri, _ = _quad(10.0)
    box = pos.copy()
    box[:, 2] = 1.0
    scene = Scene.from_arrays(np.vstack([pos, box * 0.2 + [0, 0, 0.5]]), np.vstack([tri, tri + 4]),
                              materials=[Material(metallic=1.0, roughness=0.3)],
                              lights=[Light(kind="point", position=(1, 1, 4), intensity=30, radius=0.2)])
    r = render(scene, _top_camera(24), RenderSettings.max_quality(), threads=2)
    assert all(r.counters[k] == 0 for k in NEW_COUNTERS)
    report = price(r, "mobile", 30)
    assert all(report.energy_j[b] == 0.0 for b in ("texture", "texture_dram", "area_lights", "alpha_test"))
    # Priced without the new counters at all (what the model saw before they existed): the same energy.
    before = dataclasses.replace(r, counters={k: v for k, v in r.counters.items() if k not in NEW_COUNTERS})
    assert price(before, "mobile", 30).dynamic_energy_j == report.dynamic_energy_j


def test_one_texture_shared_by_materials_and_hashed() -> None:
    pos, tri, uv = _quad()
    tex = _checker()
    mats = [Material(base_color_texture=0), Material(base_color=(0.5, 1, 1), base_color_texture=0)]
    a = Scene.from_arrays(pos, tri, uvs=uv, textures=[tex], materials=mats, material_ids=[0, 1])
    img = tex.image.copy()
    img[0, 0, 0] ^= 1
    b = Scene.from_arrays(pos, tri, uvs=uv, textures=[Texture(img, name="checker")], materials=mats,
                          material_ids=[0, 1])
    clamp = Scene.from_arrays(pos, tri, uvs=uv, textures=[Texture(tex.image, wrap_u="clamp")], materials=mats,
                              material_ids=[0, 1])
    assert len({a.content_hash, b.content_hash, clamp.content_hash}) == 3
    assert a.content_hash == Scene.from_arrays(pos, tri, uvs=uv, textures=[tex], materials=mats,
                                               material_ids=[0, 1]).content_hash


def test_textured_material_without_uvs_shows_the_mean() -> None:
    pos, tri, _ = _quad()
    scene = Scene.from_arrays(pos, tri, textures=[_checker()], lights=[SUN], environment=(0, 0, 0),
                              materials=[Material(base_color=(1, 1, 1), roughness=1.0, ior=1.0,
                                                  base_color_texture=0)])
    r = render(scene, _top_camera(8, fov=0.3), RenderSettings(shadow_samples=0), threads=1)
    assert np.allclose(r.image, r.image[0, 0], atol=1e-6)  # one colour: the 1x1 mip level
    assert r.image[0, 0, 0] == pytest.approx(0.5, abs=0.01)


def test_degenerate_and_huge_uvs_render_finite() -> None:
    """Zero UV area (every vertex at one UV) reads the finest level at that UV; huge UVs wrap; grazing
    views of a textured plane stay finite."""
    pos, tri, _ = _quad(4.0)
    tex = _checker(8)
    mat = Material(base_color=(1, 1, 1), roughness=1.0, ior=1.0, base_color_texture=0)
    huge = 1e6 + np.array([[0, 0], [3, 0], [3, 3], [0, 3]])
    grazing = Camera.look_at((0, -2.0, 0.01), (0, 2.0, 0.0), (0, 0, 1), 0.5, 16, 16)
    for uvs in (np.full((4, 2), 0.3), huge):
        scene = Scene.from_arrays(pos, tri, uvs=uvs, textures=[tex], materials=[mat], lights=[SUN],
                                  environment=(0, 0, 0))
        for cam in (_top_camera(16), grazing):
            img = render(scene, cam, RenderSettings(shadow_samples=0), threads=1).image
            assert np.all(np.isfinite(img)) and img.min() >= 0.0 and img.max() <= 1.0 + 1e-5
    flat = Scene.from_arrays(pos, tri, uvs=np.full((4, 2), 0.3), textures=[tex], materials=[mat],
                             lights=[SUN], environment=(0, 0, 0))
    img = render(flat, _top_camera(16, fov=0.5), RenderSettings(shadow_samples=0), threads=1).image
    native = sim_core._core.NativeTexture.from_rgba8(tex.rgba(), True, 0, 0)
    assert np.allclose(img, native.sample(0.3, 0.3, 0.0)[:3], atol=1e-6)  # the finest level at (0.3, 0.3)


def test_hashed_alpha_blends_over_samples() -> None:
    """A hashed-alpha card of alpha 0.3 over a white emitter stops ~30 % of the samples."""
    pos, tri, _ = _quad(4.0)
    card = pos * 0.5 + [0, 0, 1]
    scene = Scene.from_arrays(np.vstack([pos, card]), np.vstack([tri, tri + 4]), material_ids=[0, 0, 1, 1],
                              materials=[Material(base_color=(0, 0, 0), emission=(1, 1, 1)),
                                         Material(base_color=(0, 0, 0), roughness=1.0, ior=1.0, alpha=0.3,
                                                  alpha_mode="hashed")],
                              environment=(0, 0, 0))
    assert "alpha_cutouts" in scene.stats["effects"]
    r = render(scene, _top_camera(32, fov=0.4), RenderSettings(mode="fsaa", block=4, max_depth=0), threads=2)
    assert r.image[..., 0].mean() == pytest.approx(0.7, abs=0.03)
    assert r.counters["alpha_tests"] > 0 and r.counters["rays_alpha"] > 0
    opaque = Scene.from_arrays(np.vstack([pos, card]), np.vstack([tri, tri + 4]), material_ids=[0, 0, 1, 1],
                               materials=[Material(emission=(1, 1, 1)), Material(alpha=0.3)])
    assert "alpha_cutouts" not in opaque.stats["effects"]  # alpha mode "opaque": alpha is ignored


# ---- lights ----------------------------------------------------------------------------------------


def test_light_from_blender_units_and_area_shapes() -> None:
    m = np.eye(4)
    m[:3, 3] = (1, 2, 3)
    p = Light.from_blender("POINT", m, 1000.0, shadow_soft_size=0.25)
    assert p.intensity == pytest.approx(1000 / (4 * math.pi)) and p.radius == 0.25
    assert p.direction == (0, 0, -1)
    s = Light.from_blender("SPOT", m, 500.0, spot_size=1.0, spot_blend=0.3, exposure=1.0)
    assert s.intensity == pytest.approx(1000 / (4 * math.pi)) and s.spot_angle == 0.5 and s.spot_blend == 0.3
    sun = Light.from_blender("SUN", m, 3.0, angle=0.1)
    assert sun.intensity == 3.0 and sun.radius == pytest.approx(0.05)
    scaled = m.copy()
    scaled[:3, :3] = np.diag([2.0, 0.5, 1.0])
    rect = Light.from_blender("AREA", scaled, 100.0, shape="RECTANGLE", size=1.0, size_y=3.0)
    assert (rect.size, rect.size_y, rect.shape) == (2.0, 1.5, "rectangle")
    assert rect.intensity == pytest.approx(100 / (math.pi * 3.0))  # radiance of a Lambertian emitter
    disk = Light.from_blender("AREA", m, 100.0, shape="DISK", size=2.0)
    assert disk.shape == "ellipse" and disk.area == pytest.approx(math.pi)
    assert disk.intensity == pytest.approx(100 / math.pi**2)
    with pytest.raises(ValueError, match="zero size"):
        Light.from_blender("AREA", m, 100.0, shape="SQUARE", size=0.0)
    with pytest.raises(ValueError, match="zero size"):
        Light(kind="area", size=0.0)
    with pytest.raises(ValueError, match="tangent"):
        Light(kind="area", size=1.0, direction=(1, 0, 0), tangent=(2, 0, 0))
    with pytest.raises(ValueError, match="POINT, SPOT, SUN or AREA"):
        Light.from_blender("HEMI", m, 1.0)


@pytest.mark.parametrize("light", [
    Light(kind="point", position=(0.5, 0.3, 3.0), intensity=20.0, radius=0.5),
    Light(kind="sun", direction=(0.2, 0.1, -1.0), intensity=3.0, radius=math.radians(8)),
    Light(kind="area", position=(0.5, 0.3, 3.0), intensity=20.0, size=1.0, shape="disk"),
], ids=["point_radius", "sun_angle", "area"])
def test_soft_shadows_from_emitter_size(light: Light) -> None:
    """Sized emitters cast penumbras with N shadow samples, hard shadows with 1, none with 0."""
    pos, tri, _ = _quad(8.0)
    blocker = pos * 0.15 + [0, 0, 1.0]
    scene = Scene.from_arrays(np.vstack([pos, blocker]), np.vstack([tri, tri + 4]), materials=[FLAT],
                              lights=[light], environment=(0, 0, 0))
    cam = _top_camera(48, height=4.0, fov=0.5)
    floor = None

    def partial(samples: int) -> int:
        nonlocal floor
        r = render(scene, cam, RenderSettings(shadow_samples=samples, max_depth=0), threads=2)
        lit = render(scene, cam, RenderSettings(shadow_samples=0, max_depth=0), threads=2).image[..., 0]
        floor = r.aovs["object_id"] == 0
        frac = r.image[..., 0][floor] / np.maximum(lit[floor], 1e-9)
        return int(np.count_nonzero((frac > 0.05) & (frac < 0.95)))

    assert partial(16) > 3 * max(partial(1), 1) and partial(0) == 0
    assert floor is not None and floor.any()


# ---- glossy reflections ------------------------------------------------------------------------------


def _stripes_and_floor(metal: Material) -> Scene:
    """A wall of horizontal emissive bands (0.25 m, alternating lit and black) behind a metal floor: their
    mirror images are horizontal bands across the floor."""
    floor, tri, _ = _quad(8.0)
    bands, btri, mids = [], [], []
    for i in range(40):  # 10 m high, 20 m wide: what a rough lobe reflects is wall, not the black sky
        z0 = i * 0.25
        base = 4 * i
        bands += [[-10.0, 2.0, z0], [10.0, 2.0, z0], [10.0, 2.0, z0 + 0.25], [-10.0, 2.0, z0 + 0.25]]
        btri += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
        mids += [1 + i % 2] * 2
    pos = np.vstack([floor, np.asarray(bands, np.float32)])
    tris = np.vstack([tri, np.asarray(btri) + 4])
    mats = [metal, Material(base_color=(0, 0, 0), emission=(1, 1, 1)), Material(base_color=(0, 0, 0))]
    return Scene.from_arrays(pos, tris, materials=mats, material_ids=[0, 0, *mids],
                             object_ids=[0, 0] + [1] * len(mids), environment=(0, 0, 0))


def _reflection(metal: Material, settings: RenderSettings) -> np.ndarray:
    """The floor rows of the image (each row crosses the reflection of one band height)."""
    cam = Camera.look_at((0.0, -3.0, 1.2), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), 0.8, 64, 48)
    r = render(_stripes_and_floor(metal), cam, settings, threads=2)
    keep = (r.aovs["object_id"] == 0).all(axis=1)  # image rows that show only floor
    return r.image[keep]


def _band_contrast(img: np.ndarray) -> float:
    """Mean step between neighbouring rows of the row-averaged image (averaging a row cancels noise)."""
    return float(np.abs(np.diff(img[..., 0].mean(axis=1))).mean())


@pytest.mark.parametrize("env_filter", ["off", "bartlett"])
def test_rough_metal_floor_is_not_a_mirror(env_filter: str) -> None:
    settings = RenderSettings.max_quality().replace(env_filter=env_filter)
    mirror = _reflection(Material(base_color=(1, 1, 1), metallic=1.0, roughness=0.0), settings)
    rough = _reflection(Material(base_color=(1, 1, 1), metallic=1.0, roughness=0.45), settings)
    assert _band_contrast(mirror) > 0.1
    assert _band_contrast(rough) < 0.35 * _band_contrast(mirror)  # the bands blur out
    assert rough[..., 0].mean() == pytest.approx(mirror[..., 0].mean(), rel=0.25)  # about the same light


def test_metal_reflections_take_the_base_colour() -> None:
    gold = _reflection(Material(base_color=(1.0, 0.6, 0.2), metallic=1.0, roughness=0.2),
                       RenderSettings(max_depth=1))
    r, g, b = (float(gold[..., c].mean()) for c in range(3))
    assert r > g > b and b / r == pytest.approx(0.2, abs=0.08)


# ---- world ----------------------------------------------------------------------------------------


def test_world_strength_rotation_and_clamped_texels() -> None:
    pos, tri, _ = _quad(0.01, z=-100.0)
    cam = Camera.look_at((0, 0, 0), (1, 0, 0), (0, 0, 1), 0.2, 8, 8)  # looks along +X at the horizon
    const = Scene.from_arrays(pos, tri, environment=(0.2, 0.4, 0.1), environment_strength=2.5)
    assert np.allclose(render(const, cam, threads=1).image, [0.5, 1.0, 0.25], atol=1e-6)
    sky = np.zeros((16, 32, 3), np.float32)
    sky[7:9, 8, :] = 5.0  # a bright spot on the horizon at u = 0.25..0.28: direction +Y (Cycles' mapping)
    sky[0, 0, 0] = -1e-6  # a tiny negative texel, as Blender's HDRIs hold
    sky[0, 1, 1] = np.nan
    with pytest.warns(UserWarning, match="clamped 1 value.*1 non-finite"):
        plain = Scene.from_arrays(pos, tri, environment=sky)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        turned = Scene.from_arrays(pos, tri, environment=sky, environment_rotation=math.pi / 2)
    assert render(plain, cam, threads=1).image.max() == 0.0
    # The map is read at R_z(90 deg) * direction: looking along +X reads the map's +Y direction (the spot).
    assert render(turned, cam, threads=1).image.max() == pytest.approx(5.0)
    with pytest.raises(ValueError, match="strength"):
        Scene.from_arrays(pos, tri, environment_strength=-1.0)
    with pytest.raises(ValueError, match="rotation"):
        Scene.from_arrays(pos, tri, environment_rotation=float("nan"))


@pytest.mark.blender
def test_blenders_bundled_hdris_load_clamped(tmp_path) -> None:
    """Seven of Blender's eight studio-light HDRIs hold tiny negative texels: clamped with a warning,
    never rejected, and they light a scene."""
    import os

    bpy = pytest.importorskip("bpy")
    folder = os.path.join(bpy.utils.system_resource("DATAFILES"), "studiolights", "world")
    files = sorted(f for f in os.listdir(folder) if f.endswith(".exr"))
    assert len(files) >= 8
    clamped = 0
    pos, tri, _ = _quad()
    for name in files:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            env = sim_core.load_exr(os.path.join(folder, name))
        clamped += any("clamped" in str(w.message) for w in caught)
        assert env.dtype == np.float32 and np.all(np.isfinite(env)) and env.min() >= 0.0
        scene = Scene.from_arrays(pos, tri, environment=env)
        img = render(scene, _top_camera(8), RenderSettings(max_depth=0), threads=1).image
        assert np.all(np.isfinite(img)) and img.mean() > 0
    assert clamped >= 7
