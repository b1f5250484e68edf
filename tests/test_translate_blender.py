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

    if not _TMP:  # removed when the test process ends
        _TMP.append(tempfile.TemporaryDirectory(prefix="translate-test-"))
    return Path(_TMP[0].name) / "cycles.png"


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


def checker_material(size: int = 16):
    """A Principled material whose Base Color is an Image Texture (a packed 2x2 checker, mirrored)."""
    img = bpy.data.images.new("Checker", size, size, alpha=True)
    px = np.zeros((size, size, 4), np.float32)
    half = size // 2
    px[:half, :half] = px[half:, half:] = (1.0, 0.0, 0.0, 1.0)  # Blender rows: bottom first
    px[:half, half:] = px[half:, :half] = (0.0, 0.0, 1.0, 0.5)
    img.pixels.foreach_set(px.reshape(-1))
    img.pack()
    mat = bpy.data.materials.new("Checker")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.extension = "MIRROR"
    bsdf = nodes["Principled BSDF"]
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    return mat, px


def hdri_world(strength: float, rotation_z: float):
    """Blender's bundled forest HDRI as the world (Environment Texture behind a Mapping node)."""
    from pathlib import Path

    from blend_scenes import common
    from blend_scenes.scenes.artist import bundled_hdri

    return common.world_exr(Path(bundled_hdri()), strength, rotation_z)


def uv_box_mesh(name: str, material):
    """A 2 m cube with Blender's own UV map, wearing ``material``."""
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_cube(bm, size=2.0, calc_uvs=True)
    bm.to_mesh(me)
    bm.free()
    me.materials.append(material)
    return me


def test_textures_area_lights_and_the_hdri_are_carried(scene):
    mat, px = checker_material()
    add(scene, "Box", uv_box_mesh("Box", mat), (0, 0, 0))
    plain = add(scene, "NoUVs", cube_mesh("NoUVsMesh"), (4, 0, 0))  # bmesh's cube has no UV map
    plain.data.materials.append(mat)
    shapes = {"SQUARE": (1.0, 0.0), "RECTANGLE": (2.0, 0.5), "DISK": (1.5, 0.0), "ELLIPSE": (1.0, 3.0)}
    for i, (shape, (size, size_y)) in enumerate(shapes.items()):
        data = bpy.data.lights.new(f"Area{shape}", "AREA")
        data.shape, data.size, data.size_y, data.energy = shape, size, size_y, 100.0 * (i + 1)
        light = add(scene, f"Area{shape}", data, (i, 0, 5))
        light.scale = (2.0, 1.0, 1.0)
    image = hdri_world(strength=1.5, rotation_z=0.6)

    t = translate_for_render(scene)
    sd = t.scene_data
    # the checker travels as a texture (rows top first, sRGB bytes, alpha because the material reads it)
    assert len(sd.textures) == 1
    tex = sd.textures[0]
    assert tex.image.dtype == np.uint8 and tex.image.shape == (16, 16, 4) and tex.colorspace == "srgb"
    assert np.array_equal(tex.image, np.round(px[::-1] * 255).astype(np.uint8))
    assert tex.wrap_u == tex.wrap_v == "mirror"
    box_mat = sd.materials[int(sd.material_ids[sd.object_ids == sd.object_names.index("Box")][0])]
    assert box_mat.base_color_texture == 0 and box_mat.alpha_mode == "hashed"
    # the cube's UVs: Blender's own, per corner
    box_uvs = sd.uvs[np.unique(sd.triangles[sd.object_ids == sd.object_names.index("Box")])]
    assert box_uvs.min() >= 0.0 and box_uvs.max() <= 1.0 and len(np.unique(box_uvs, axis=0)) >= 8
    # the mesh without UVs shows the image's mean colour instead (noted)
    flat = sd.materials[int(sd.material_ids[sd.object_ids == sd.object_names.index("NoUVs")][0])]
    assert flat.base_color_texture is None
    assert flat.base_color == pytest.approx((0.5, 0.0, 0.5))  # linear mean of red and blue
    assert any("without a UV map" in n.message for n in t.notes)
    # area lights: every shape, sizes after the object's X scale, Cycles' radiance
    areas = {lt.name: lt for lt in sd.lights}
    for i, (shape, (size, size_y)) in enumerate(shapes.items()):
        lt = areas[f"Area{shape}"]
        height = size_y if shape in ("RECTANGLE", "ELLIPSE") else size
        assert lt.kind == "area" and lt.size == pytest.approx(2 * size) and lt.size_y == pytest.approx(height)
        assert lt.shape == ("rectangle" if shape in ("SQUARE", "RECTANGLE") else "ellipse")
        area = 2 * size * height * (math.pi / 4 if lt.shape == "ellipse" else 1.0)
        assert lt.intensity == pytest.approx(100.0 * (i + 1) / (math.pi * area))
    # the HDRI: Blender's pixels, row 0 at the top, negative texels clamped (noted), strength and rotation
    w, h = image.size
    raw = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(raw)
    raw = raw.reshape(h, w, 4)[::-1, :, :3]
    assert sd.environment.shape == (h, w, 3)
    assert np.array_equal(sd.environment, np.maximum(raw, 0.0))
    assert (sd.environment_strength, sd.environment_rotation) == (pytest.approx(1.5), pytest.approx(0.6))
    assert any("clamped" in n.message and "negative" in n.message for n in t.notes)


def test_scene_file_of_a_translation_round_trips(scene, tmp_path):
    from sim_core.loaders.scene_file import read_scene_file, write_scene_file

    import sim_core

    mat, _ = checker_material()
    ob = add(scene, "Cube", cube_mesh("CubeMesh"), (0, 0, 0))
    ob.data.materials.append(mat)
    sun = add(scene, "Sun", bpy.data.lights.new("Sun", "SUN"), (0, 0, 5))
    sun.data.angle = 0.05
    hdri_world(strength=0.8, rotation_z=0.0)
    first = translate_for_render(scene)
    id_a = write_scene_file(tmp_path / "a.rbscene", first.scene_data, first.notes)
    second = translate_for_render(scene)  # a second translation of the same scene: the same bytes
    id_b = write_scene_file(tmp_path / "b.rbscene", second.scene_data, second.notes)
    assert id_a == id_b
    content = read_scene_file(tmp_path / "a.rbscene")
    assert content.notes == [n.to_dict() for n in first.notes]
    assert write_scene_file(tmp_path / "c.rbscene", content.data, content.notes) == id_a
    assert sim_core.Scene.from_scene_file(tmp_path / "a.rbscene").content_hash == \
        sim_core.Scene.from_scene_data(first.scene_data).content_hash


def instance_on_points_tree(instance_object):
    """A geometry-nodes group: the modified mesh plus an instance of ``instance_object`` on each point."""
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = tree.nodes, tree.links
    group_in, group_out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    info = nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = instance_object
    join = nodes.new("GeometryNodeJoinGeometry")
    links.new(group_in.outputs[0], on_points.inputs["Points"])
    links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    links.new(on_points.outputs[0], join.inputs[0])
    links.new(group_in.outputs[0], join.inputs[0])
    links.new(join.outputs[0], group_out.inputs[0])
    return tree


def test_geometry_nodes_instances_text_holdouts_and_camera_visibility(scene):
    grid = bpy.data.meshes.new("Grid")
    grid.from_pydata([(x, y, 0.0) for y in (-2, 0, 2) for x in (-2, 0, 2)], [],
                     [(0, 1, 4, 3), (1, 2, 5, 4), (3, 4, 7, 6), (4, 5, 8, 7)])
    scatter = add(scene, "Scatter", grid, (0, 0, 0))
    pebble = add(scene, "Pebble", sphere_mesh("PebbleMesh"), (0, 0, -50))
    pebble.hide_render = True  # only its instances render
    scatter.modifiers.new("Scatter", "NODES").node_group = instance_on_points_tree(pebble)
    text = add(scene, "Label", bpy.data.curves.new("Label", "FONT"), (0, 3, 0))
    text.data.body = "Hi"
    held = add(scene, "Held", cube_mesh("HeldMesh"), (5, 0, 0))
    held.is_holdout = True
    held.pass_index = 7
    ghost = add(scene, "Ghost", cube_mesh("GhostMesh"), (-5, 0, 0))
    ghost.visible_camera = False

    t = translate_for_render(scene)
    sd = t.scene_data
    names = sd.object_names
    pebbles = [n for n in names if n.startswith("PebbleMesh in Scatter")]
    assert len(pebbles) == 9, names  # one instance on each grid point, the source itself hidden
    # nine instances, one mesh read for them all
    pebble_triangles = [int(np.count_nonzero(sd.object_ids == names.index(n))) for n in pebbles]
    assert len(set(pebble_triangles)) == 1
    assert t.stats["mesh_reads"] == t.stats["unique_meshes"] == 4  # grid, pebble, text, held cube
    # the text renders once (as the mesh Blender evaluates it to), not twice
    text_objects = [n for n in names if "Label" in n]
    assert text_objects == ["Label"]
    text_eval = text.evaluated_get(bpy.context.evaluated_depsgraph_get())
    expected = len(text_eval.to_mesh().loop_triangles)
    text_eval.to_mesh_clear()
    assert int(np.count_nonzero(sd.object_ids == names.index(text_objects[0]))) == expected
    # the Object Index pass value of each object (an instance takes its instanced object's)
    assert len(t.pass_indices) == len(names)
    assert t.pass_indices[names.index("Held")] == 7 and t.pass_indices[names.index(pebbles[0])] == 0
    # a holdout renders as a plain surface, an object invisible to camera rays is left out: both noted
    assert "Held" in names and "Ghost" not in names
    notes = t.notes_text(limit=50)
    assert "'Held': holdout" in notes and "'Ghost': invisible to camera" in notes


# -- incremental translation (the viewport's view_update) ------------------------------------------------
class ViewportUpdates:
    """What the render engine's view_update does on each depsgraph update, run from Blender's
    depsgraph_update_post handler (view_update itself needs a GUI): the incremental translation through
    one cache, next to a fresh full translation of the same depsgraph to compare with."""

    def __init__(self) -> None:
        from addon.translate import TranslationCache

        self.cache = TranslationCache()
        self.incremental = None
        self.fresh = None
        self.changes = []

    def __enter__(self):
        bpy.app.handlers.depsgraph_update_post.append(self.on_update)
        return self

    def __exit__(self, *exc) -> None:
        bpy.app.handlers.depsgraph_update_post.remove(self.on_update)

    def on_update(self, _scene, depsgraph) -> None:
        from addon.translate import depsgraph_updates, translate_update

        self.changes = depsgraph_updates(depsgraph)
        self.incremental = translate_update(depsgraph, self.cache, force=not self.cache.meshes)
        self.fresh = translate(depsgraph, camera=False)

    def edit(self, change) -> tuple[object, int]:
        """Apply ``change()``, let the depsgraph evaluate it; (the incremental translation or None, meshes
        it extracted)."""
        before = self.cache.extractions
        self.incremental, self.fresh = "none yet", None
        change()
        bpy.context.evaluated_depsgraph_get().update()
        assert self.fresh is not None, "the depsgraph reported no update"
        return self.incremental, self.cache.extractions - before


def assert_same_translation(got, want) -> None:
    a, b = got.scene_data, want.scene_data
    for name in ("positions", "normals", "triangles", "material_ids", "object_ids", "uvs"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)
    assert a.object_names == b.object_names
    assert a.materials == b.materials and a.lights == b.lights
    assert isinstance(a.environment, np.ndarray) == isinstance(b.environment, np.ndarray)
    if isinstance(a.environment, np.ndarray):
        np.testing.assert_array_equal(a.environment, b.environment)
    else:
        assert a.environment == b.environment
    assert a.environment_strength == b.environment_strength
    assert a.environment_rotation == b.environment_rotation
    assert len(a.textures) == len(b.textures)
    for ta, tb in zip(a.textures, b.textures, strict=True):
        np.testing.assert_array_equal(ta.image, tb.image)
        assert (ta.colorspace, ta.wrap_u, ta.wrap_v) == (tb.colorspace, tb.wrap_u, tb.wrap_v)
    assert got.pass_indices == want.pass_indices
    assert [str(n) for n in got.notes] == [str(n) for n in want.notes]


def test_incremental_translation_reads_only_what_an_edit_changed(scene):
    shared = cube_mesh("Shared")
    a = add(scene, "A", shared, (-3, 0, 0))
    b = add(scene, "B", shared, (0, 0, 0))  # a linked duplicate: one extracted mesh for both
    c = add(scene, "C", sphere_mesh("Ball"), (3, 0, 0))
    c.modifiers.new("Subdivision", "SUBSURF").levels = 1
    red, blue = emissive("Red", (1, 0, 0)), emissive("Blue", (0, 0, 1))
    shared.materials.append(red)
    c.data.materials.append(blue)
    lamp = add(scene, "Lamp", bpy.data.lights.new("Lamp", "POINT"), (0, -4, 4))
    with ViewportUpdates() as vp:
        first, reads = vp.edit(lambda: setattr(a, "location", (-3, 0, 0.5)))
        assert reads == 2 and first.stats["unique_meshes"] == 2  # the first translation reads everything
        assert_same_translation(first, vp.fresh)

        # moving an object: every mesh reused, only its instance transformed again
        moved, reads = vp.edit(lambda: setattr(a, "location", (-3, 1, 0.5)))
        assert reads == 0 and moved.stats["mesh_reuses"] == 2
        assert_same_translation(moved, vp.fresh)
        assert not np.array_equal(moved.scene_data.positions, first.scene_data.positions)

        # the camera moving changes nothing the simulator sees (it is read at every draw)
        still, reads = vp.edit(lambda: setattr(scene.camera, "location", (0.0, -11.0, 0.0)))
        assert still is None and reads == 0

        # a material edit: materials read again, no mesh
        def recolour():
            blue.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 9.0
        recoloured, reads = vp.edit(recolour)
        assert reads == 0
        assert_same_translation(recoloured, vp.fresh)
        assert recoloured.scene_data.materials != moved.scene_data.materials

        # a light edit: no mesh
        lit, reads = vp.edit(lambda: setattr(lamp.data, "energy", 321.0))
        assert reads == 0
        assert_same_translation(lit, vp.fresh)

        # a geometry edit of one object: exactly its mesh is read again
        def reshape():
            c.data.vertices[0].co.z += 0.25
            c.data.update()
        reshaped, reads = vp.edit(reshape)
        assert reads == 1 and reshaped.stats["mesh_reuses"] == 1
        assert_same_translation(reshaped, vp.fresh)

        # hiding and deleting objects: gone from the scene, their cached meshes dropped
        hidden, _ = vp.edit(lambda: setattr(c, "hide_viewport", True))
        assert "C" not in hidden.scene_data.object_names
        assert_same_translation(hidden, vp.fresh)
        assert len(vp.cache.meshes) == 1
        gone, _ = vp.edit(lambda: bpy.data.objects.remove(b))
        assert gone.scene_data.object_names == ["A"]
        assert_same_translation(gone, vp.fresh)

        # an object added: read once, the others reused
        added, reads = vp.edit(lambda: add(scene, "D", cube_mesh("New"), (0, 2, 0)))
        assert reads == 1 and set(added.scene_data.object_names) == {"A", "D"}
        assert_same_translation(added, vp.fresh)


def test_incremental_translation_of_instances_and_modifiers(scene):
    """Collection instances share their source's mesh (read once) and moving an instancer re-reads
    nothing; an edited modifier re-reads exactly its object's mesh; a source edit updates every
    instance. Each step equals a fresh translation."""
    visibility_scene(scene)
    ball = add(scene, "Ball", sphere_mesh("BallMesh"), (0, 0, 2))
    sub = ball.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = 1
    instancer = bpy.data.objects["Instancer0"]
    source = bpy.data.objects["Source"]
    with ViewportUpdates() as vp:
        first, reads = vp.edit(lambda: setattr(ball, "location", (0, 0, 2.5)))
        # Shown, HiddenRender (shown in the viewport), the source (once for both instances), the ball
        assert reads == 4 and first.stats["instances"] == 5
        assert_same_translation(first, vp.fresh)
        moved, reads = vp.edit(lambda: setattr(instancer, "location", (3, 1, 0)))
        assert reads == 0
        assert_same_translation(moved, vp.fresh)
        finer, reads = vp.edit(lambda: setattr(sub, "levels", 2))
        assert reads == 1 and finer.stats["triangles"] > moved.stats["triangles"]
        assert_same_translation(finer, vp.fresh)

        def grow():
            source.data.vertices[0].co.z += 0.5
            source.data.update()
        grown, reads = vp.edit(grow)
        assert reads == 1  # one mesh behind both instances
        assert_same_translation(grown, vp.fresh)


def test_incremental_translation_keeps_images_and_the_world_until_they_change(scene):
    """Image pixels and the world are kept across edits (their notes reported again each time); a
    material edit re-reads materials (not the image), a world edit the world."""
    mat, _px = checker_material()
    image = mat.node_tree.nodes["Image Texture"].image
    image.colorspace_settings.name = "Linear Rec.2020"  # read as linear, with a note
    box = add(scene, "Box", uv_box_mesh("Box", mat), (0, 0, 0))
    hdri_world(strength=1.5, rotation_z=0.6)
    with ViewportUpdates() as vp:
        first, _ = vp.edit(lambda: setattr(box, "location", (0, 0, 0.1)))
        assert any("colour space" in n.message for n in first.notes)
        assert_same_translation(first, vp.fresh)
        images = dict(vp.cache.images)

        def rougher():
            mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.8
        rough, reads = vp.edit(rougher)
        assert reads == 0 and vp.cache.images == images  # the image was not read again
        assert_same_translation(rough, vp.fresh)
        assert rough.scene_data.materials[0].roughness == pytest.approx(0.8)

        def brighter():
            scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 3.0
        bright, reads = vp.edit(brighter)
        assert reads == 0 and bright.scene_data.environment_strength == pytest.approx(3.0)
        assert_same_translation(bright, vp.fresh)


def test_translation_render_holds_viewport_workers_still(scene):
    """translate_for_render runs Blender's render operator with a render engine it registers for the
    purpose: no viewport worker may run Python meanwhile. A worker busy rendering is stopped before and
    resumed after; between Blender's render_pre and render_post it never ran."""
    import threading
    import time

    from addon.core.engine_frame import RenderCancelled
    from addon.core.progressive import ProgressiveDriver, ViewRequest

    add(scene, "Cube", cube_mesh("C"), (0, 0, 0))
    ticks: list[float] = []
    window: dict[str, float] = {}
    started = threading.Event()

    def busy_render(payload, w, h, should_stop):
        started.set()
        for _ in range(4000):  # about 8 s of bands unless stopped
            ticks.append(time.monotonic())
            if should_stop():
                raise RenderCancelled
            time.sleep(0.002)
        return np.zeros((h, w, 4), np.float32), payload

    def pre(*_args):
        window["pre"] = time.monotonic()

    def post(*_args):
        window["post"] = time.monotonic()

    driver = ProgressiveDriver(busy_render, (1.0,))
    bpy.app.handlers.render_pre.append(pre)
    bpy.app.handlers.render_post.append(post)
    try:
        driver.update(ViewRequest("view", 8, 8))
        assert started.wait(5)
        translate_for_render(scene)
        assert "pre" in window and "post" in window
        assert not [t for t in ticks if window["pre"] <= t <= window["post"]]
        time.sleep(0.1)
        assert ticks[-1] > window["post"]  # the stopped render started again afterwards
        assert driver.cancelled >= 1
    finally:
        bpy.app.handlers.render_pre.remove(pre)
        bpy.app.handlers.render_post.remove(post)
        driver.close()
