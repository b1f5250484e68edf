"""The translator's pure half (no bpy): Blender corners to per-vertex arrays, instance transforms, material,
light and world conversions with their notes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addon.core.scene_translation import (
    ImageData,
    LightInputs,
    MaterialInputs,
    MeshArrays,
    Notes,
    SceneAssembler,
    WorldInputs,
    corner_mesh,
    environment_from_inputs,
    light_from_inputs,
    material_from_inputs,
    transform_mesh,
)


def quad_corners(flat: bool = True):
    """A unit quad as Blender stores it: 4 vertices, 4 corners, 2 loop triangles."""
    co = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    cv = np.array([0, 1, 2, 3])
    cn = np.tile([0, 0, 1], (4, 1)).astype(np.float32)
    if not flat:
        cn[2] = [0, 0.6, 0.8]
    tc = np.array([[0, 1, 2], [0, 2, 3]])
    return co, cv, cn, tc


def test_corner_mesh_welds_equal_corners_and_keeps_seams():
    co, cv, cn, tc = quad_corners()
    m = corner_mesh(co, cv, cn, tc, np.zeros(2))
    assert m.positions.shape == (4, 3) and m.triangles.shape == (2, 3)
    assert np.array_equal(m.positions[m.triangles], co[cv[tc]])
    # a UV seam at one corner of a vertex shared by two faces: that vertex splits in two
    cv2 = np.array([0, 1, 2, 0, 2, 3])
    cn2 = np.tile([0, 0, 1], (6, 1)).astype(np.float32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0.5, 0], [1, 1], [0, 1]], np.float32)
    m2 = corner_mesh(co, cv2, cn2, np.array([[0, 1, 2], [3, 4, 5]]), np.zeros(2), uv)
    assert m2.positions.shape[0] == 5  # vertex 0 twice (two UVs), vertex 2 once (same UV)
    assert np.array_equal(m2.uvs[m2.triangles], uv[np.array([[0, 1, 2], [3, 4, 5]])])


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 40), st.integers(0, 2**31 - 1))
def test_corner_mesh_reproduces_every_corner(n_tri, seed):
    rng = np.random.default_rng(seed)
    co = rng.normal(size=(10, 3)).astype(np.float32)
    corners = 3 * n_tri
    cv = rng.integers(0, 10, corners)
    normals = rng.choice([-1.0, 0.0, 1.0], size=(corners, 3)).astype(np.float32)
    uvs = rng.choice([0.0, 0.5], size=(corners, 2)).astype(np.float32)
    tc = rng.permutation(corners).reshape(-1, 3)
    m = corner_mesh(co, cv, normals, tc, rng.integers(0, 3, n_tri), uvs)
    assert np.array_equal(m.positions[m.triangles], co[cv[tc]])
    assert np.array_equal(m.normals[m.triangles], normals[tc])
    assert np.array_equal(m.uvs[m.triangles], uvs[tc])
    assert m.positions.shape[0] <= corners


def test_corner_mesh_rejects_bad_indices():
    co, cv, cn, tc = quad_corners()
    with pytest.raises(ValueError, match="out of range"):
        corner_mesh(co, cv, cn, tc + 10, np.zeros(2))
    with pytest.raises(ValueError, match="vertex out of range"):
        corner_mesh(co, cv + 4, cn, tc, np.zeros(2))


def test_transform_mirror_flips_winding_and_keeps_normals_outward():
    co, cv, cn, tc = quad_corners()
    m = corner_mesh(co, cv, cn, tc, np.zeros(2))
    mirror = np.diag([1.0, 1.0, -1.0, 1.0])
    p, n, t = transform_mesh(m, mirror)
    geometric = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    assert np.allclose(n, [0, 0, -1])
    assert np.all(np.einsum("ij,ij->i", geometric, n[t[:, 0]]) > 0)  # winding agrees with the normal
    with pytest.raises(ValueError, match="singular"):
        transform_mesh(m, np.diag([1.0, 0.0, 1.0, 1.0]))


def test_normals_follow_the_inverse_transpose():
    co, cv, cn, tc = quad_corners(flat=False)
    m = corner_mesh(co, cv, cn, tc, np.zeros(2))
    shear = np.eye(4)
    shear[0, 1] = 2.0
    _, n, _ = transform_mesh(m, shear)
    # a normal stays perpendicular to the transformed surface's tangents
    tangent = shear[:3, :3] @ np.array([1.0, 0, 0])
    assert np.allclose(n @ tangent, 0.0, atol=1e-6)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)


def test_assembler_shares_mesh_arrays_between_instances():
    co, cv, cn, tc = quad_corners()
    asm = SceneAssembler()
    asm.add_mesh("quad", corner_mesh(co, cv, cn, tc, np.array([0, 1])))

    def make(name, rgb):
        return asm.material_index(name, lambda: material_from_inputs(MaterialInputs(name, rgb), asm.notes))

    red, blue = make("red", (1, 0, 0)), make("blue", (0, 0, 1))
    m2 = np.eye(4)
    m2[:3, 3] = [5, 0, 0]
    asm.add_instance("quad", np.eye(4), [red, blue], "a", pass_index=3)
    asm.add_instance("quad", m2, [blue], "b")  # one slot: both triangles blue
    data = asm.build()
    assert data.object_names == ["a", "b"] and asm.pass_indices == [3, 0]
    assert data.triangles.shape == (4, 3) and data.positions.shape == (8, 3)
    assert data.material_ids.tolist() == [red, blue, blue, blue]
    assert data.object_ids.tolist() == [0, 0, 1, 1]
    assert np.allclose(data.positions[4:] - data.positions[:4], [5, 0, 0])


def test_assembler_reuses_instance_transforms_and_equals_a_fresh_build(monkeypatch):
    """With a transforms table (the viewport's), an instance whose mesh and matrix are unchanged is not
    transformed again; the arrays equal a build without the table, and the table follows the scene."""
    from addon.core.scene_translation import assembler as assembler_module

    co, cv, cn, tc = quad_corners()
    quad = corner_mesh(co, cv, cn, tc, np.array([0, 1]))
    calls = []
    real = assembler_module.transform_mesh
    monkeypatch.setattr(assembler_module, "transform_mesh", lambda m, x: calls.append(1) or real(m, x))

    def scene(shift: float, table):
        asm = SceneAssembler()
        asm.add_mesh("quad", quad)
        asm.add_mesh("quad2", quad)
        m2, m3 = np.eye(4), np.eye(4)
        m2[:3, 3] = [5, 0, 0]
        m3[:3, 3] = [0, shift, 0]
        asm.add_instance("quad", np.eye(4), [0], "a")
        asm.add_instance("quad", m2, [0], "b")
        asm.add_instance("quad2", m3, [0, 1], "c")
        asm.materials = [material_from_inputs(MaterialInputs(n, (1, 1, 1)), asm.notes) for n in "xy"]
        return asm.build(transforms=table)

    table: dict = {}
    first = scene(1.0, table)
    assert len(calls) == 3 and len(table) == 3
    moved = scene(2.0, table)  # only "c" moved
    assert len(calls) == 4 and len(table) == 3
    calls.clear()
    fresh = scene(2.0, None)
    assert len(calls) == 3
    for name in ("positions", "normals", "triangles", "material_ids", "object_ids"):
        np.testing.assert_array_equal(getattr(moved, name), getattr(fresh, name))
        assert getattr(moved, name).dtype == getattr(fresh, name).dtype
    assert not np.array_equal(first.positions, moved.positions)
    assert moved.material_ids.tolist() == [0, 0, 0, 0, 0, 1]


def test_assembler_without_geometry_says_so():
    with pytest.raises(ValueError, match="no visible geometry"):
        SceneAssembler().build()
    asm = SceneAssembler()
    asm.add_mesh("empty", MeshArrays(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), None,
                                     np.zeros((0, 3), np.uint32), np.zeros(0, np.int32)))
    asm.add_instance("empty", np.eye(4), [], "e")
    with pytest.raises(ValueError, match="no visible geometry"):
        asm.build()


def test_material_values_are_clamped_with_notes():
    notes = Notes()
    m = material_from_inputs(MaterialInputs("odd", base_color=(1.2, -0.1, 0.5), roughness=1.4, ior=12.0,
                                            emission_color=(1.0, 0.5, 0.0), emission_strength=4.0), notes)
    assert m.base_color == (1.2, 0.0, 0.5)
    assert m.roughness == 1.0 and m.ior == 4.0
    assert m.emission == (4.0, 2.0, 0.0)
    text = " | ".join(str(n) for n in notes)
    assert "roughness 1.4 clamped" in text and "IOR 12 clamped" in text and "negative base colour" in text


def test_image_mean_is_linear():
    srgb_half = np.full((2, 2, 4), 188, np.uint8)  # sRGB 188/255 ~ linear 0.5
    img = ImageData("half", srgb_half, "srgb")
    assert img.mean_linear_rgb() == pytest.approx((0.5029,) * 3, abs=1e-3)
    assert ImageData("raw", srgb_half, "linear").mean_linear_rgb()[0] == pytest.approx(188 / 255)


def test_lights_in_cycles_units():
    notes = Notes()
    m = np.eye(4)
    m[:3, 3] = [1, 2, 3]
    point = light_from_inputs(LightInputs("p", "POINT", m, 1000.0, shadow_soft_size=0.25, exposure=1.0),
                              notes)
    assert point.kind == "point" and point.intensity == pytest.approx(2000.0 / (4 * math.pi))
    assert point.position == (1, 2, 3) and point.radius == 0.25
    sun = light_from_inputs(LightInputs("s", "SUN", np.eye(4), 3.0, angle=0.02), notes)
    assert sun.intensity == 3.0 and sun.radius == pytest.approx(0.01) and sun.direction == (0, 0, -1)
    spot = light_from_inputs(LightInputs("sp", "SPOT", np.eye(4), 100.0, spot_size=1.0, spot_blend=0.3),
                             notes)
    assert spot.spot_angle == pytest.approx(0.5) and spot.spot_blend == pytest.approx(0.3)
    area = light_from_inputs(LightInputs("a", "AREA", np.diag([2.0, 1.0, 1.0, 1.0]), 100.0, shape="RECTANGLE",
                                         size=1.0, size_y=0.5), notes)
    assert area.kind == "area" and (area.size, area.size_y) == (2.0, 0.5)
    assert area.intensity == pytest.approx(100.0 / (math.pi * 1.0))
    # "Normalize" off (checked against Cycles: a 3 x 0.6 m rectangle renders 1.80x brighter): power per m^2
    raw = light_from_inputs(LightInputs("a", "AREA", np.diag([2.0, 1.0, 1.0, 1.0]), 100.0, shape="RECTANGLE",
                                        size=1.0, size_y=0.5, normalize=False), notes)
    assert raw.intensity == pytest.approx(area.intensity * 2.0 * 0.5)
    assert light_from_inputs(LightInputs("off", "POINT", np.eye(4), 0.0), notes) is None
    assert light_from_inputs(LightInputs("flat", "AREA", np.eye(4), 10.0, size=0.0), notes) is None
    text = " | ".join(str(n) for n in notes)
    assert "emits nothing" in text and "light 'flat': left out" in text


def test_world_map_clamps_and_keeps_strength_and_rotation():
    notes = Notes()
    px = np.ones((4, 8, 4), np.float32)
    px[0, 0, 0] = -0.01
    px[1, 1, 1] = np.nan
    env, strength, rotation = environment_from_inputs(
        WorldInputs(image=ImageData("hdr", px, "linear"), strength=2.0, rotation_z=0.7), notes)
    assert env.shape == (4, 8, 3) and env.dtype == np.float32
    assert env[0, 0, 0] == 0 and env[1, 1, 1] == 0 and env[2, 2, 2] == 1.0
    assert (strength, rotation) == (2.0, 0.7)
    assert any("clamped 1 negative and 1 non-finite" in str(n) for n in notes)
    colour, strength, rotation = environment_from_inputs(WorldInputs(color=(0.1, 0.2, 0.3), strength=2.0,
                                                                     rotation_z=0.7), notes)
    assert colour == pytest.approx((0.1, 0.2, 0.3)) and (strength, rotation) == (2.0, 0.0)


def test_textured_material_shares_one_texture_and_falls_back_without_uvs():
    asm = SceneAssembler()
    px = np.zeros((4, 4, 4), np.uint8)
    px[..., 3] = 255
    px[:2, :, :3] = 255  # top half white
    image = ImageData("checker", px, "srgb")
    inputs = MaterialInputs("Checker", (1.0, 1.0, 1.0), base_image=image, wrap="mirror")
    with_uvs = asm.principled_index("Checker", lambda: inputs, uvs=True)
    again = asm.principled_index("Checker", lambda: pytest.fail("read once"), uvs=True)
    without = asm.principled_index("Checker", lambda: inputs, uvs=False)
    assert with_uvs == again != without
    textured, flat = asm.materials[with_uvs], asm.materials[without]
    assert textured.base_color_texture == 0 and textured.base_color == (1.0, 1.0, 1.0)
    assert textured.alpha_mode == "opaque"
    assert flat.base_color_texture is None and flat.base_color == pytest.approx((0.5,) * 3)
    tex = asm.textures[0]
    assert len(asm.textures) == 1 and tex.wrap_u == tex.wrap_v == "mirror" and tex.image.shape == (4, 4, 3)
    assert any("without a UV map" in str(n) for n in asm.notes)
    # the image's alpha travels only when the material reads it
    cutout = asm.principled_index("Leaf", lambda: MaterialInputs("Leaf", base_image=image, image_alpha=True),
                                  uvs=True)
    assert asm.materials[cutout].alpha_mode == "hashed" and asm.textures[1].image.shape == (4, 4, 4)


def test_constant_alpha_is_cycles_stochastic_alpha():
    notes = Notes()
    m = material_from_inputs(MaterialInputs("veil", alpha=0.3), notes)
    assert (m.alpha, m.alpha_mode) == (0.3, "hashed")
    assert material_from_inputs(MaterialInputs("solid"), notes).alpha_mode == "opaque"


# -- what the viewport's incremental translation keeps ------------------------------------------------
def test_translation_cache_forgets_exactly_what_an_update_changed() -> None:
    from addon.core.scene_translation.cache import Cached, TranslationCache, Update

    def filled() -> TranslationCache:
        c = TranslationCache()
        c.meshes = {"m": Cached("mesh")}
        c.materials = {"mat": Cached("inputs")}
        c.images = {"img": Cached("pixels")}
        c.world = ("World", Cached("env"))
        return c

    c = filled()
    c.invalidate([Update("OBJECT", "MESH", transform=True, name="Cube"), Update("SCENE"),
                  Update("CAMERA", name="Cam"), Update("COLLECTION", geometry=True), Update("LIGHT")])
    assert c.meshes and c.materials and c.images and c.world and not c.dirty_objects  # nothing to forget
    c.invalidate([Update("OBJECT", "MESH", geometry=True, name="Cube"), Update("MESH", geometry=True)])
    assert c.dirty_objects == {"Cube"} and c.meshes and c.materials and c.world  # re-read by object
    c = filled()
    c.invalidate([Update("MATERIAL", shading=True, name="Red")])
    assert not c.materials and c.images and c.world is not None
    c = filled()
    c.invalidate([Update("WORLD", name="World")])
    assert c.world is None and c.materials and c.images
    c = filled()
    c.invalidate([Update("IMAGE", name="Checker")])
    assert not c.images and not c.materials and c.world is None
    c = filled()
    c.invalidate([Update("SOMETHING_NEW")])  # an ID type this translator does not know
    assert not c.materials and c.world is None and c.meshes
    c = filled()
    c.dirty_objects.add("Cube")
    c.meshes["n"] = Cached("other")
    c.keep_only(["n"], [])
    assert list(c.meshes) == ["n"] and not c.materials and not c.dirty_objects
    c.clear()
    assert not (c.meshes or c.materials or c.images or c.transforms) and c.world is None


def test_cached_notes_are_reported_again_on_reuse() -> None:
    from addon.core.scene_translation import Notes
    from addon.core.scene_translation.cache import Cached

    first = Notes()
    first.warn("image 'A'", "could not be loaded")
    cached = Cached(None, tuple(first))
    again = Notes()
    assert cached.replay(again) is None and [str(n) for n in again] == [str(n) for n in first]
    cached.replay(again)
    assert len(again) == 1  # the same note about the same thing is kept once
