"""The depsgraph translator inside real Blender (bpy 5.0.1): what it keeps and leaves out against what Cycles
renders, render-level modifiers, instances read once, materials, lights, world and notes."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytestmark = pytest.mark.blender
bpy = pytest.importorskip("bpy")

from addon.translate import translate, translate_for_render  # noqa: E402


@pytest.fixture
def scene():
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 96, 54, 100
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.location = (0.0, -12.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)  # looks down +Y
    cam.data.lens = 20.0
    sc.collection.objects.link(cam)
    sc.camera = cam
    return sc


def cube_mesh(name: str, size: float = 1.0):
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=size)
    bm.to_mesh(me)
    bm.free()
    return me


def sphere_mesh(name: str):
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=8, v_segments=4, radius=0.6)
    bm.to_mesh(me)
    bm.free()
    return me


def add(sc, name, data, location, collection=None):
    ob = bpy.data.objects.new(name, data)
    ob.location = location
    (collection or sc.collection).objects.link(ob)
    return ob


def emissive(name, rgb):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0, 0, 0, 1)
    bsdf.inputs["Emission Color"].default_value = (*rgb, 1)
    bsdf.inputs["Emission Strength"].default_value = 5.0
    return mat


def visibility_scene(sc):
    """Objects at known x positions along a row the camera sees, each with its own emissive colour:
    shown (x=-6), hidden for render (x=-3), in an excluded collection (x=0), that collection instanced
    twice (x=+3 and x=+6, the instances offset from the source), and one disabled in the view layer."""
    red, green, blue = emissive("Red", (1, 0, 0)), emissive("Green", (0, 1, 0)), emissive("Blue", (0, 0, 1))
    shown = add(sc, "Shown", cube_mesh("ShownMesh"), (-6, 0, 0))
    shown.data.materials.append(red)
    hidden = add(sc, "HiddenRender", cube_mesh("HiddenMesh"), (-3, 0, 0))
    hidden.data.materials.append(green)
    hidden.hide_render = True
    excluded = bpy.data.collections.new("Excluded")
    sc.collection.children.link(excluded)
    source = add(sc, "Source", cube_mesh("SourceMesh"), (0, 0, 0), excluded)
    source.data.materials.append(blue)
    bpy.context.view_layer.layer_collection.children["Excluded"].exclude = True
    for i, x in enumerate((3.0, 6.0)):
        inst = bpy.data.objects.new(f"Instancer{i}", None)
        inst.instance_type = "COLLECTION"
        inst.instance_collection = excluded
        inst.location = (x, 0, 0)
        sc.collection.objects.link(inst)
    return {"Shown": -6.0, "HiddenRender": -3.0, "Source": 0.0, "Source in Instancer0": 3.0,
            "Source in Instancer1": 6.0}


def cycles_row(sc) -> np.ndarray:
    """Cycles' (emission-only, few samples) render of the row: the mean colour in each object's column."""
    sc.render.engine = "CYCLES"
    sc.cycles.samples = 4
    sc.cycles.use_denoising = False
    sc.cycles.device = "CPU"
    sc.world = None
    bpy.ops.render.render()
    bpy.data.images["Render Result"].save_render(filepath=str(_tmp_png()))
    img = bpy.data.images.load(str(_tmp_png()))
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1, :, :3]


_TMP: list = []


def _tmp_png():
    import tempfile
    from pathlib import Path

    if not _TMP:
        _TMP.append(Path(tempfile.mkdtemp(prefix="translate-test-")) / "cycles.png")
    return _TMP[0]


def column_of(x: float, sc) -> int:
    """Pixel column where world x (at y=0, z=0) lands for the fixture's camera."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    co = world_to_camera_view(sc, sc.camera, Vector((x, 0.0, 0.0)))
    return int(co.x * sc.render.resolution_x)


def test_render_translation_keeps_what_cycles_renders(scene):
    where = visibility_scene(scene)
    t = translate_for_render(scene)
    kept = set(t.scene_data.object_names)
    assert kept == {"Shown", "Source in Instancer0", "Source in Instancer1"}
    image = cycles_row(scene)
    mid = image.shape[0] // 2
    for name, x in where.items():
        seen = float(image[mid - 2: mid + 3, column_of(x, scene)].max()) > 0.2
        assert seen == (name in kept), f"{name}: Cycles shows it {seen}, translation keeps it {name in kept}"
    # the two instances share one mesh read from Blender once
    assert t.stats["unique_meshes"] == 2 and t.stats["mesh_reads"] == 2
    sd = t.scene_data
    xs = [float(sd.positions[sd.triangles[sd.object_ids == i].reshape(-1)][:, 0].mean())
          for i in range(len(sd.object_names))]
    assert sorted(xs) == pytest.approx([-6.0, 3.0, 6.0], abs=1e-5)


def test_viewport_depsgraph_follows_viewport_visibility(scene):
    visibility_scene(scene)
    t = translate(bpy.context.evaluated_depsgraph_get())
    # hide_render is a render setting: the viewport still shows the object
    assert set(t.scene_data.object_names) == {"Shown", "HiddenRender", "Source in Instancer0",
                                              "Source in Instancer1"}
    assert t.stats["mode"] == "VIEWPORT"


def test_render_level_modifiers(scene):
    sphere = add(scene, "Glass", sphere_mesh("GlassMesh"), (0, 0, 0))
    mod = sphere.modifiers.new("Subdivision", "SUBSURF")
    mod.levels, mod.render_levels = 1, 3
    viewport = translate(bpy.context.evaluated_depsgraph_get())
    render = translate_for_render(scene)
    assert render.stats["mode"] == "RENDER"
    assert render.stats["triangles"] == 16 * viewport.stats["triangles"]  # two more levels: 4x4 the faces
    mod.levels = 3  # the viewport at render level gives the same mesh
    assert translate(bpy.context.evaluated_depsgraph_get()).stats["triangles"] == render.stats["triangles"]


def test_translate_for_render_restores_the_scene_and_reports_errors(scene):
    add(scene, "Cube", cube_mesh("C"), (0, 0, 0))
    scene.render.engine = "CYCLES"
    scene.render.use_compositing = True
    translate_for_render(scene)
    assert scene.render.engine == "CYCLES" and scene.render.use_compositing
    for ob in list(scene.objects):
        if ob.type == "MESH":
            bpy.data.objects.remove(ob)
    with pytest.raises(ValueError, match="no visible geometry"):
        translate_for_render(scene)
    assert scene.render.engine == "CYCLES"
    scene.camera = None
    with pytest.raises(ValueError, match="no active camera"):
        translate_for_render(scene)


def test_linked_duplicates_share_and_mirror(scene):
    me = cube_mesh("Shared")
    a = add(scene, "A", me, (-2, 0, 0))
    b = add(scene, "B", me, (2, 0, 0))
    b.scale = (-1, 1, 1)
    t = translate_for_render(scene)
    assert t.stats["unique_meshes"] == 1 and t.stats["instances"] == 2
    sd = t.scene_data
    for i in range(2):
        tri = sd.triangles[sd.object_ids == i]
        p = sd.positions
        geo = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
        centre = p[tri.reshape(-1)].mean(axis=0)
        outward = p[tri[:, 0]] - centre
        assert np.all(np.einsum("ij,ij->i", geo, outward) > 0), "faces must stay outward after mirroring"
    assert a.name == "A"


def test_unsupported_node_setup_is_approximated_and_noted(scene):
    ob = add(scene, "Noisy", cube_mesh("NoisyMesh"), (0, 0, 0))
    mat = bpy.data.materials.new("Procedural")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    checker = nodes.new("ShaderNodeTexChecker")
    checker.inputs["Color1"].default_value = (1, 0, 0, 1)
    checker.inputs["Color2"].default_value = (0, 0, 1, 1)
    links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    noise = nodes.new("ShaderNodeTexNoise")
    links.new(noise.outputs["Fac"], bsdf.inputs["Roughness"])
    ob.data.materials.append(mat)
    t = translate_for_render(scene)
    m = t.scene_data.materials[0]
    assert m.base_color == pytest.approx((0.5, 0.0, 0.5))
    assert m.roughness == pytest.approx(0.5)  # the socket's own value
    text = t.notes_text()
    assert "Checker Texture" in text and "Noise Texture" in text
    assert all(n.severity == "warning" for n in t.notes if "Texture" in n.message)
