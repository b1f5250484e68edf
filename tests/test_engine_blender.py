"""The Render Budget GPU render engine inside real Blender (the bpy 5.0.1 module, background): it
registers (with its Render Properties generated from the optimiser's space), renders a frame with
every pass and its metadata, follows the store under a budget through an animation (CSV beside the
frames, the same settings the playback logic picks), and falls back to the manual settings."""

from __future__ import annotations

import csv
import importlib
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.store import ParetoStore
from tests.addon_support import EXT_MODULE, dev_extension, disable_dev, enable_dev, synthetic_store

pytestmark = pytest.mark.blender
bpy = pytest.importorskip("bpy")

ENGINE = "RENDER_BUDGET"
PASS_NAMES = ("Combined", "Depth", "Normal", "IndexOB", "Sample Kind", "Power")


@pytest.fixture(scope="module")
def ext(tmp_path_factory: pytest.TempPathFactory):
    with dev_extension(bpy, tmp_path_factory.mktemp("ext")) as mod:
        yield mod


def ext_module(name: str):
    return importlib.import_module(f"{EXT_MODULE}.{name}")


def cheap(sc) -> None:
    """Manual settings that trace fast (tests are about plumbing, not image quality)."""
    eng = sc.render_budget_engine
    eng.sampling, eng.shadow_samples, eng.ao_samples, eng.max_depth = "1spp", "1", "0", "1"


@pytest.fixture
def scene(ext):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    sc = bpy.context.scene
    sc.render.engine = ENGINE
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 64, 36, 100
    sc.render.fps, sc.render.fps_base = 24, 1.0
    cheap(sc)
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 0.5))
    bpy.context.object.pass_index = 3
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    light.data.energy = 800.0
    light.location = (2.0, -2.0, 4.0)
    sc.collection.objects.link(light)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    aim(cam, (0.0, -5.0, 2.5))
    return sc


def aim(cam, eye, target=(0.0, 0.0, 0.4)) -> None:
    from mathutils import Vector

    cam.location = eye
    cam.rotation_euler = (Vector(target) - Vector(eye)).to_track_quat("-Z", "Y").to_euler()


def orbit_camera(sc, frames: int = 8) -> None:
    cam = sc.camera
    sc.frame_start, sc.frame_end = 1, frames
    for f in range(1, frames + 1):
        a = 2 * math.pi * (f - 1) / frames
        aim(cam, (5 * math.cos(a), 5 * math.sin(a), 2.0))
        cam.keyframe_insert("location", frame=f)
        cam.keyframe_insert("rotation_euler", frame=f)


def load_store(tmp_path: Path, store: Any = None) -> None:
    """The synthetic store (or ``store``) as the scene's store (after recording the camera path it
    summarises)."""
    sc = bpy.context.scene
    if sc.frame_end > 48:
        sc.frame_start, sc.frame_end = 1, 8
    assert bpy.ops.render_budget.record_path_animation() == {"FINISHED"}
    f = tmp_path / "store.json"
    f.write_text((store or synthetic_store()).to_json())
    assert bpy.ops.render_budget.load_store(filepath=str(f)) == {"FINISHED"}


def render_still(sc, path: Path, fmt: str = "PNG") -> None:
    sc.render.image_settings.media_type = "IMAGE"
    sc.render.image_settings.file_format = fmt
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


# -- registration -------------------------------------------------------------------------------------
def registered_engine():
    """The engine class Blender has registered under our id (None when there is none)."""
    return bpy.types.RenderEngine.bl_rna_get_subclass_py(ENGINE)


def test_the_engine_registers_with_its_properties_and_borrowed_panels(ext) -> None:
    from service.params import renderable_space

    assert registered_engine().bl_label == "Render Budget GPU"
    assert ENGINE in bpy.types.RENDER_PT_color_management.COMPAT_ENGINES
    assert ENGINE in bpy.types.EEVEE_MATERIAL_PT_surface.COMPAT_ENGINES
    rna = bpy.types.Scene.bl_rna.properties["render_budget_engine"].fixed_type.bl_rna.properties
    for p in renderable_space().parameters:  # one property per parameter, every value a store may name
        items = [i.identifier for i in rna[p.name].enum_items]
        assert items == [str(v) for v in p.values] and rna[p.name].default == str(p.values[p.max_quality])
    disable_dev()
    try:
        assert registered_engine() is None
        with pytest.raises(TypeError, match=ENGINE):
            bpy.context.scene.render.engine = ENGINE  # gone from the engine menu
        assert ENGINE not in bpy.types.RENDER_PT_color_management.COMPAT_ENGINES
        assert not hasattr(bpy.types.Scene, "render_budget_engine")
        assert not [h for h in bpy.app.handlers.render_init if h.__module__.startswith(EXT_MODULE)]
    finally:
        enable_dev(bpy, Path())


def test_the_compositor_offers_every_pass(scene) -> None:
    tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
    scene.compositing_node_group = tree
    node = tree.nodes.new("CompositorNodeRLayers")
    node.scene = scene
    offered = [o.name for o in node.outputs if o.enabled]
    assert offered == ["Image", "Alpha", *PASS_NAMES[1:]]


# -- a frame with every pass --------------------------------------------------------------------------
def test_a_frame_renders_with_every_pass_and_its_metadata(scene, tmp_path) -> None:
    from PIL import Image

    render = ext_module("engine.render")
    held = {}

    def read_back(layer) -> None:  # what Blender's render result holds, read before end_result
        for p in layer.passes:
            flat = np.empty(len(p.rect) * p.channels, dtype=np.float32)
            p.rect.foreach_get(flat)
            held[p.name] = flat.reshape(36, 64, p.channels)[::-1]

    render.inspect_result = read_back
    try:
        render_still(scene, tmp_path / "still.png")
    finally:
        render.inspect_result = None
    last = render.last_frame
    assert last is not None and last.frame == 1 and last.csv_path is None
    assert last.layer_passes == PASS_NAMES and tuple(held) == PASS_NAMES
    out = last.output
    np.testing.assert_array_equal(held["Combined"], out.combined)
    for name in PASS_NAMES[1:]:
        np.testing.assert_array_equal(held[name], out.passes[name])
    depth, index = held["Depth"][..., 0], held["IndexOB"][..., 0]
    hit = depth < 1e9
    assert hit.any() and (~hit).any()  # the ground and the cube, and sky above them
    assert set(np.unique(index).tolist()) == {0.0, 3.0}  # the cube carries its pass index
    cube = index == 3.0
    assert depth[cube].mean() < depth[hit & ~cube].mean() + 1.0  # the cube stands in front of the ground
    np.testing.assert_allclose(np.linalg.norm(held["Normal"][hit], axis=-1), 1.0, atol=1e-3)
    assert set(np.unique(held["Sample Kind"]).tolist()) <= {0.0, 1.0, 2.0}
    assert held["Power"].sum() * 1e-6 == pytest.approx(out.dynamic_power_w, rel=1e-5)
    assert held["Power"][hit].mean() > held["Power"][~hit].mean()  # the power goes where the geometry is
    assert held["Combined"][..., 3].min() == 1.0
    # metadata in the written file
    info = Image.open(tmp_path / "still.png").info
    assert info["render_budget.source"] == "manual"
    assert "sampling=1spp" in info["render_budget.settings"]
    assert "max_depth=1" in info["render_budget.settings"]
    assert float(info["render_budget.simulated_power_w"]) == pytest.approx(out.power_w, rel=1e-5)
    assert info["render_budget.profile"] == "mobile" and info["render_budget.fps"] == "24"
    assert "no store" in info["render_budget.note"]


def test_an_approximated_material_is_reported_with_the_frame(scene, tmp_path) -> None:
    """A procedural texture the simulator cannot shade: the frame renders, and its metadata (and the
    Last Render panel's record) say what the translation approximated."""
    from PIL import Image

    mat = bpy.data.materials.new("Marble")
    nodes = mat.node_tree.nodes
    noise = nodes.new("ShaderNodeTexNoise")
    mat.node_tree.links.new(noise.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    bpy.data.objects["Cube"].data.materials.append(mat)
    render_still(scene, tmp_path / "marble.png")
    out = ext_module("engine.render").last_frame.output
    assert "Marble" in out.scene_notes
    assert "Marble" in Image.open(tmp_path / "marble.png").info["render_budget.scene_notes"]


def test_exr_header_and_transparent_film(scene, tmp_path) -> None:
    import OpenEXR

    scene.render.film_transparent = True
    scene.render_budget_engine.sampling = "undersample_4x4"
    render_still(scene, tmp_path / "still.exr", fmt="OPEN_EXR")
    out = ext_module("engine.render").last_frame.output
    sky = out.passes["Depth"][..., 0] > 1e9
    assert np.all(out.combined[sky, 3] == 0.0) and np.all(out.combined[~sky, 3] == 1.0)
    assert 1.0 in np.unique(out.passes["Sample Kind"])  # undersampling interpolates similar pixels
    with OpenEXR.File(str(tmp_path / "still.exr")) as f:  # the header is only readable while open
        assert f.header()["render_budget.settings"].startswith("sampling=undersample_4x4")
        rgba = np.array(f.channels()["RGBA"].pixels)
    np.testing.assert_allclose(rgba[..., 3], out.combined[..., 3], atol=1e-3)


def test_lens_shift_renders_the_cameras_window(scene, tmp_path) -> None:
    """The camera's projection (calc_matrix_camera) gives the fov the store is looked up with; a lens
    shift moves the frame over the scene (the cube moves the other way in the image)."""
    from service.store.camera import projection_window

    sc = scene
    camera_vfov = ext_module("camera_path").camera_vfov
    proj = sc.camera.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=64, y=36)
    vfov, full_w, full_h, _x0, _y0 = projection_window(proj, 64, 36)
    assert (full_w, full_h) == (64, 36) and vfov == pytest.approx(camera_vfov(sc.camera, sc), rel=1e-5)
    render = ext_module("engine.render")

    def cube_x() -> float:
        index = render.last_frame.output.passes["IndexOB"][..., 0]
        return float(np.argwhere(index == 3.0)[:, 1].mean())

    render_still(sc, tmp_path / "centred.png")
    centred = cube_x()
    sc.camera.data.shift_x = 0.125  # an eighth of the frame width (the larger side)
    render_still(sc, tmp_path / "shifted.png")
    out = render.last_frame.output
    assert out.combined.shape == (36, 64, 4)
    assert centred - cube_x() == pytest.approx(8.0, abs=1.0)
    assert "window" in out.metadata()["render_budget.note"]


def test_manual_settings_win_when_chosen_even_with_a_store(scene, tmp_path) -> None:
    load_store(tmp_path)
    scene.render_budget_engine.settings_source = "MANUAL"
    render_still(scene, tmp_path / "m.png")
    s = ext_module("engine.render").last_frame.output.settings
    assert s.source == "manual" and s.values()["max_depth"] == 1 and s.note == ""
    scene.render_budget_engine.settings_source = "STORE"
    scene.render_budget.budget_mode, scene.render_budget.power_budget = "POWER", 0.0  # no budget set
    render_still(scene, tmp_path / "n.png")
    s = ext_module("engine.render").last_frame.output.settings
    assert s.source == "manual" and "no budget" in s.note


def test_an_orthographic_camera_is_refused_with_a_message(scene, tmp_path) -> None:
    scene.camera.data.type = "ORTHO"
    before = ext_module("engine.render").last_frame
    with pytest.raises(RuntimeError, match="perspective"):
        render_still(scene, tmp_path / "ortho.png")
    assert ext_module("engine.render").last_frame is before


# -- an animation under the store -----------------------------------------------------------------------
def test_an_animation_follows_the_store_under_the_budget(scene, tmp_path) -> None:
    from PIL import Image

    from addon.core.playback_logic import PlaybackDriver
    from service.params import renderable_space

    sc = scene
    orbit_camera(sc, frames=8)
    store = synthetic_store()
    store.meta.update(figures_resolution=[32, 18], display_pricing="tiles:ssim")  # priced for 32x18
    load_store(tmp_path, store)
    props = sc.render_budget
    props.budget_mode, props.power_budget, props.filter_period = "POWER", 3.3, 0.1
    sc.render_budget_engine.measure_error = True
    render = ext_module("engine.render")
    render._final_scenes.clear()
    builds = render._final_scenes.builds
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = str(tmp_path / "frames" / "shot_")
    bpy.ops.render.render(animation=True)

    rows = list(csv.DictReader((tmp_path / "frames" / "shot_render_budget.csv").open()))
    assert [int(r["frame"]) for r in rows] == list(range(1, 9))
    assert render._final_scenes.builds == builds + 1  # only the camera moves: one BVH for the whole shot
    # the same frames through the playback logic (fresh filter, scene time, the camera the handler reads)
    # on the store as the scene holds it (its figures rounded by the store format: the filter paces in
    # predicted error, so the unrounded synthetic store can break a tie another way)
    space = renderable_space()
    drv = PlaybackDriver(ParetoStore.from_json((tmp_path / "store.json").read_text()), 0.1)
    camera_vfov = ext_module("camera_path").camera_vfov
    for f, row in zip(range(1, 9), rows, strict=True):
        sc.frame_set(f)
        frame = drv.step(np.array(sc.camera.matrix_world), camera_vfov(sc.camera, sc), 64 / 36, (f - 1) / 24,
                         "POWER", 3.3)
        want = space.values_of(space.indices_of(frame.active_settings))
        assert row["source"] == "store"
        assert {k: row[k] for k in want} == {k: str(v) for k, v in want.items()}
        assert float(row["predicted_power_w"]) == pytest.approx(frame.predicted_power_w, rel=1e-5)
        assert float(row["simulated_power_w"]) > 0
        # measured against the reference: 0 where the frontier point shown renders this small scene
        # exactly as the maximum-quality settings do
        assert 0.0 <= float(row["measured_error"]) < 0.5
        info = Image.open(tmp_path / "frames" / f"shot_{f:04d}.png").info
        assert info["render_budget.source"] == "store"
        assert float(info["render_budget.predicted_power_w"]) == pytest.approx(frame.predicted_power_w,
                                                                              rel=1e-5)
        # the predictions hold for the store's 32x18 display, the simulated figures for this 64x36 render
        assert (row["predicted_for"], row["image_resolution"]) == ("32x18", "64x36")
        assert info["render_budget.predicted_for"] == "32x18"
    assert len({(r["max_depth"], r["resolution_scale"], r["shadow_samples"]) for r in rows}) > 1
    assert any(float(r["measured_error"]) > 0.0 for r in rows)
    # simulated power follows the settings: frames traced at a larger resolution scale cost more
    by_scale: dict[float, list[float]] = {}
    for r in rows:
        by_scale.setdefault(float(r["resolution_scale"]), []).append(float(r["simulated_power_w"]))
    assert len(by_scale) > 1
    assert max(by_scale[min(by_scale)]) < min(by_scale[max(by_scale)])
    # a second animation render is a new job: a new filter and a new CSV with the same rows
    first = [(r["frame"], r["max_depth"], r["resolution_scale"], r["shadow_samples"]) for r in rows]
    bpy.ops.render.render(animation=True)
    again = list(csv.DictReader((tmp_path / "frames" / "shot_render_budget.csv").open()))
    assert [(r["frame"], r["max_depth"], r["resolution_scale"], r["shadow_samples"]) for r in again] == first


def test_store_frames_are_priced_at_the_frame_rate_the_lookup_used(scene, tmp_path) -> None:
    """The scene runs at 30 fps, the store was priced for 24: a frame whose settings the store chose is
    priced at the rate its lookup targeted (the store's 24 fps; 12 fps with the Frame rate option), not
    the scene's, so the simulated power, the metadata's ``fps`` and the CSV's ``fps_target`` agree with
    the lookup; the viewport prices playback's settings at the same rate."""
    from PIL import Image

    sc = scene
    sc.render.fps = 30
    orbit_camera(sc, frames=2)
    store = synthetic_store(timed=True)
    store.meta["static_power_w"] = 0.2  # another frame rate can be asked for
    load_store(tmp_path, store)
    props = sc.render_budget
    # an error budget: the same setting at both rates (power repriced per rate keeps its order)
    props.budget_mode, props.error_budget, props.filter_period = "ERROR", 0.05, 0.0
    render = ext_module("engine.render")
    outs = {}
    for fps in (0.0, 12.0):  # 0: the store's own
        props.fps = fps
        render_still(sc, tmp_path / f"still{fps:g}.png")
        out = outs[fps] = render.last_frame.output
        info = Image.open(tmp_path / f"still{fps:g}.png").info
        assert out.settings.source == "store" and out.deadline_met  # a 64x36 frame keeps up
        assert out.fps == out.achieved_fps == (fps or 24.0)
        assert info["render_budget.fps"] == info["render_budget.lookup_fps_target"] == f"{fps or 24.0:g}"
    assert outs[0.0].settings.indices == outs[12.0].settings.indices
    # the same frame's energy drawn at half the rate: half the dynamic power
    assert outs[12.0].dynamic_power_w == pytest.approx(outs[0.0].dynamic_power_w / 2, rel=1e-5)
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = str(tmp_path / "frames" / "shot_")
    bpy.ops.render.render(animation=True)
    rows = list(csv.DictReader((tmp_path / "frames" / "shot_render_budget.csv").open()))
    assert len(rows) == 2 and {(r["fps_target"], r["achieved_fps"]) for r in rows} == {("12", "12")}
    props.playback_enabled = True
    sc.frame_set(2)  # the playback handler applies the store's settings; the viewport shows those
    settings, _store = render.viewport_settings(sc)
    assert settings.fps_target == pytest.approx(12.0) and settings.pricing_fps(30.0) == pytest.approx(12.0)


def test_the_viewport_status_names_the_display_the_store_predicts_for(ext) -> None:
    """The status line puts the simulated power of the image shown beside the store's prediction, and
    says which display that prediction holds for."""
    from dataclasses import replace
    from types import SimpleNamespace

    from addon.core.viewport import ViewInfo

    render = ext_module("engine.render")
    info = ViewInfo("settings", "store", 1.0, 2.0, 2.5, 0.0123, (32, 18), 0.01, 30.0, 30.0, "640x360")
    frame = SimpleNamespace(info=info, final=True, level=0, levels=1)
    text = render._viewport_status(frame, None, (64, 36))
    assert "(store, 640x360: 2.500 W, error 0.0123)" in text
    unknown = SimpleNamespace(info=replace(info, predicted_for=""), final=True, level=0, levels=1)
    assert "(store, size unknown: 2.500 W" in render._viewport_status(unknown, None, (64, 36))
