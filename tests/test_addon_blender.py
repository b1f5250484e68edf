"""The add-on inside real Blender (the bpy 5.0.1 module): registration, path recording, playback from a
store saved in the .blend, and bad input. The add-on folder is staged into a temp folder (this environment
has the project's packages) and loaded from there as a dev extension repository."""

from __future__ import annotations

import importlib
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from service.store import ParetoStore as ParetoStoreType
from tests.addon_support import EXT_MODULE, dev_extension, disable_dev, enable_dev, synthetic_store

pytestmark = pytest.mark.blender
bpy = pytest.importorskip("bpy")


@pytest.fixture(scope="module")
def ext(tmp_path_factory: pytest.TempPathFactory):
    with dev_extension(bpy, tmp_path_factory.mktemp("ext")) as mod:
        yield mod


@pytest.fixture
def scene(ext):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 320, 180, 100
    sc.render.fps, sc.render.fps_base = 24, 1.0
    return sc


def add_camera(sc, name="Cam", lens=35.0):
    cam = bpy.data.objects.new(name, bpy.data.cameras.new(name))
    cam.data.lens = lens
    sc.collection.objects.link(cam)
    sc.camera = cam
    return cam


def add_cube(sc, size=2.0):
    import bmesh

    me = bpy.data.meshes.new("Cube")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=size)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new("Cube", me)
    sc.collection.objects.link(ob)
    return ob


def turning_camera(sc, frames=48):
    """A camera orbiting the origin (keyframed), looking through every side of the view cube."""
    cam = add_camera(sc)
    sc.frame_start, sc.frame_end = 1, frames
    for f, ang in ((1, 0.0), (frames // 2, math.pi), (frames, 2 * math.pi - 0.01)):
        cam.location = (6 * math.cos(ang), 6 * math.sin(ang), 1.0)
        cam.rotation_euler = (math.radians(85), 0.0, ang + math.pi / 2)
        cam.keyframe_insert("location", frame=f)
        cam.keyframe_insert("rotation_euler", frame=f)
    return cam


def ext_module(name: str):
    return importlib.import_module(f"{EXT_MODULE}.{name}")


# -- registration --------------------------------------------------------------------------------------
def _leftovers() -> list[str]:
    prefixes = ("POWER_", "RENDER_BUDGET_", "VIEW3D_PT_power", "VIEW3D_PT_render_budget")
    found = [n for n in dir(bpy.types) if n.startswith(prefixes)]
    if hasattr(bpy.types.Scene, "render_budget"):
        found.append("Scene.render_budget")
    if hasattr(bpy.types.WindowManager, "render_budget_runtime"):
        found.append("WindowManager.render_budget_runtime")
    for hs in (bpy.app.handlers.frame_change_post, bpy.app.handlers.load_post):
        found += [h.__name__ for h in hs if (getattr(h, "__module__", "") or "").startswith(EXT_MODULE)]
    try:
        bpy.ops.render_budget.optimize.get_rna_type()
        found.append("operator power.optimize")
    except KeyError:
        pass
    return found


def test_enable_disable_reenable_leaves_nothing_behind(ext) -> None:
    hud = ext_module("hud")
    assert not hud.is_registered()  # background mode: no draw handler at all
    assert "RENDER_BUDGET_OT_optimize" in dir(bpy.types) and hasattr(bpy.types.Scene, "render_budget")
    disable_dev()
    assert _leftovers() == []
    assert EXT_MODULE not in bpy.context.preferences.addons
    enable_dev(bpy, Path())  # the dev repo is still registered; re-enable from it
    handlers = [h for h in bpy.app.handlers.frame_change_post if h.__module__.startswith(EXT_MODULE)]
    assert len(handlers) == 1  # re-enabling does not stack handlers
    assert "RENDER_BUDGET_OT_optimize" in dir(bpy.types)
    assert not ext_module("hud").is_registered()


def test_every_operator_the_panel_offers_is_registered(ext) -> None:
    import inspect
    import re

    offered = set(re.findall(r'operator\("([a-z_]+\.[a-z_]+)"', inspect.getsource(ext_module("panels"))))
    assert len(offered) >= 8
    for idname in sorted(offered):
        group, name = idname.split(".")
        getattr(getattr(bpy.ops, group), name).get_rna_type()  # KeyError when not registered


def test_a_file_saved_with_the_old_settings_group_is_migrated_once(scene, tmp_path) -> None:
    """Files saved before the rename hold ``Scene.power_budget``; Blender keeps it as raw ID properties."""
    path_text = bpy.data.texts.new("power_budget_path")
    path_text.write('{"version": 1}')
    scene["power_budget"] = {"budget_mode": 0, "power_budget": 3.25, "error_budget": 0.015, "max_depth": 3,
                             "parameters": [{"name": "max_depth", "values": "0,1,2", "value_count": 3,
                                             "enabled": False}]}
    scene["power_budget"]["path_text"] = path_text
    blend = tmp_path / "old.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    sc = bpy.context.scene
    props = sc.render_budget
    assert "power_budget" not in sc.keys()
    assert (props.budget_mode, props.power_budget, props.max_depth) == ("POWER", 3.25, 3)
    assert math.isclose(props.error_budget, 0.015, rel_tol=1e-6)
    assert props.path_text is not None and props.path_text.as_string() == '{"version": 1}'
    assert [(p.name, p.values, p.value_count, p.enabled) for p in props.parameters] == [
        ("max_depth", "0,1,2", 3, False)]
    props.power_budget = 5.0  # migrated once: a later load keeps what the user changed
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    assert bpy.context.scene.render_budget.power_budget == 5.0


def test_settings_saved_under_older_property_names_are_moved(scene, tmp_path) -> None:
    """``camera_sampling`` (enum PATH/AIMED/AXIS) became ``view_sampling``; ``threshold_power`` became
    ``threshold_power_w``: Blender keeps the old values as raw ID properties of the group."""
    props = scene.render_budget
    props["camera_sampling"] = 1  # AIMED, stored as its item index
    props["threshold_power"] = 0.25
    blend = tmp_path / "renamed.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    props = bpy.context.scene.render_budget
    assert props.view_sampling == "aimed" and math.isclose(props.threshold_power_w, 0.25, rel_tol=1e-6)
    assert "camera_sampling" not in props.keys() and "threshold_power" not in props.keys()


# -- camera paths ---------------------------------------------------------------------------------------
def test_recorded_path_matches_matrix_world_with_parent_and_lens_animation(scene) -> None:
    sc = scene
    parent = bpy.data.objects.new("Rig", None)
    sc.collection.objects.link(parent)
    cam = add_camera(sc)
    cam.parent = parent
    sc.frame_start, sc.frame_end = 3, 27
    keys = {3: (0.0, 0.0, 24.0, 0.0), 15: (4.0, 1.2, 70.0, 1.0), 27: (-2.0, 2.5, 35.0, -1.0)}
    for f, (x, rz, lens, cy) in keys.items():
        parent.location = (x, 0.5 * x, 1.0)
        parent.rotation_euler = (0.0, 0.0, rz)
        parent.keyframe_insert("location", frame=f)
        parent.keyframe_insert("rotation_euler", frame=f)
        cam.location = (0.0, cy, 0.3)
        cam.rotation_euler = (1.2, 0.0, 0.2 * cy)
        cam.keyframe_insert("location", frame=f)
        cam.keyframe_insert("rotation_euler", frame=f)
        cam.data.lens = lens
        cam.data.keyframe_insert("lens", frame=f)
    sc.frame_set(10)
    assert bpy.ops.render_budget.record_path_animation() == {"FINISHED"}
    assert sc.frame_current == 10  # restored
    from service.camera_path import CameraPath

    path = CameraPath.from_json(sc.render_budget.path_text.as_string())
    assert len(path) == 25 and path.fps == 24.0 and path.frames[-1].time == pytest.approx(24 / 24)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    lenses = set()
    for i, f in enumerate(range(3, 28)):
        sc.frame_set(f)
        direct = np.array(cam.matrix_world)
        fr = path.frames[i]
        assert np.abs(fr.matrix_world - direct).max() < 1e-5
        # vfov against Blender's own projection matrix: P[1][1] = 1 / tan(vfov / 2)
        proj = cam.calc_matrix_camera(depsgraph, x=320, y=180)
        assert fr.vfov == pytest.approx(2 * math.atan(1 / proj[1][1]), rel=1e-5)
        assert fr.resolution == (320, 180)
        lenses.add(round(cam.data.lens, 3))
    assert len(lenses) > 10  # the lens really was animated
    # the parent's motion is in the recorded matrices
    assert np.abs(path.frames[0].matrix_world[:3, 3] - path.frames[12].matrix_world[:3, 3]).max() > 1.0


@pytest.mark.parametrize("fit", ["HORIZONTAL", "VERTICAL"])
def test_vfov_follows_sensor_fit(scene, fit: str) -> None:
    cam = add_camera(scene, lens=40)
    cam.data.sensor_fit = fit
    scene.render.resolution_x, scene.render.resolution_y = 200, 300
    cp = ext_module("camera_path")
    proj = cam.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=200, y=300)
    assert cp.camera_vfov(cam, scene) == pytest.approx(2 * math.atan(1 / proj[1][1]), rel=1e-6)


def test_viewport_keyframes_reproduce_the_sampled_poses(scene) -> None:
    """The modal recorder's keyframing step: poses written at frames come back from the animation."""
    from mathutils import Euler, Matrix

    cp = ext_module("camera_path")
    cam = add_camera(scene, "Rec")
    poses = [Matrix.LocRotScale((i, 2 - i, 1 + 0.1 * i), Euler((1.2, 0.1 * i, 3.0 + 0.7 * i)), None)
             for i in range(5)]  # yaw crosses +-pi: Euler continuity matters
    for i, m in enumerate(poses):
        cp.keyframe_pose(cam, 1 + i, m, 30.0 + i)
    for i, m in enumerate(poses):
        scene.frame_set(1 + i)
        assert np.abs(np.array(cam.matrix_world) - np.array(m)).max() < 1e-5
        assert cam.data.lens == pytest.approx(30.0 + i)


def test_record_without_camera_is_reported(scene) -> None:
    with pytest.raises(RuntimeError, match="no active camera"):
        bpy.ops.render_budget.record_path_animation()


# -- playback from a store in the .blend ------------------------------------------------------------------
def _load_store(tmp_path: Path, **kind: bool):
    f = tmp_path / "store.json"
    f.write_text(synthetic_store(**kind).to_json())
    assert bpy.ops.render_budget.load_store(filepath=str(f)) == {"FINISHED"}


def test_playback_follows_store_and_filter_and_survives_save_reload(scene, tmp_path) -> None:
    from addon.core.playback_logic import PlaybackDriver

    sc = scene
    cam = turning_camera(sc)
    add_cube(sc)
    bpy.ops.render_budget.record_path_animation()
    _load_store(tmp_path)
    props = sc.render_budget
    assert "views" in props.summary and props.store_text is not None
    props.budget_mode, props.error_budget, props.filter_period = "ERROR", 0.01, 0.5

    def play() -> list[tuple[str, str, float]]:
        out = []
        for f in range(sc.frame_start, sc.frame_end + 1):
            sc.frame_set(f)
            out.append((props.active_indices, props.target_indices, props.predicted_power))
        return out

    seen = play()
    # the same poses through the pure driver (same store, same filter, scene time)
    store = synthetic_store()
    drv = PlaybackDriver(store, 0.5)
    expected = []
    for f in range(sc.frame_start, sc.frame_end + 1):
        sc.frame_set(f)
        fr = drv.step(np.array(cam.matrix_world), ext_module("camera_path").camera_vfov(cam, sc), 320 / 180,
                      (f - 1) / 24, "ERROR", 0.01)
        expected.append((" ".join(map(str, fr.active_indices)), " ".join(map(str, fr.target_indices))))
    assert [s[:2] for s in seen] == expected
    assert len({s[1] for s in seen}) >= 3  # settings change along the path
    assert any(a != t for a, t, _ in seen)  # and the filter blends between targets
    # save, reload: store and path are in the .blend; playback gives the same answers
    blend = tmp_path / "played.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    assert bpy.context.scene.render_budget.store_text is None
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    sc = bpy.context.scene
    props = sc.render_budget
    assert props.store_text is not None and props.path_text is not None
    assert props.store_text.as_string() == synthetic_store().to_json()
    assert play() == seen


def test_budget_change_during_playback_goes_through_the_filter(scene, tmp_path) -> None:
    sc = scene
    turning_camera(sc)
    add_cube(sc)
    bpy.ops.render_budget.record_path_animation()
    _load_store(tmp_path)
    props = sc.render_budget
    props.budget_mode, props.power_budget, props.filter_period = "POWER", 1.7, 1.0
    sc.frame_set(1)
    tight = props.target_indices
    assert props.predicted_power <= 1.7
    # a looser budget: a new target, reached along the frontier (the cheap settings stay at first) ...
    props.power_budget = 10.0
    sc.frame_set(2)
    assert props.target_indices != tight and props.active_indices != props.target_indices
    assert props.playback_status == "blending" and props.predicted_power <= 10.0
    # ... a tighter one than the settings on screen: the filter goes at once to a point that keeps it
    props.power_budget = 1.7
    sc.frame_set(3)
    assert props.predicted_power <= 1.7
    sc.frame_set(2 + 26)  # more than T = 1 s later (24 fps)
    assert props.playback_status in ("on target", "blending")
    # invalid budget: reported in the status (panel and HUD show it), the stale settings are cleared
    assert props.active_indices
    props.budget_mode = "POWER"
    props.power_budget = 0.0
    sc.frame_set(30)
    assert props.playback_status.startswith("error: power budget must be > 0")
    assert (props.active_indices, props.active_settings, props.predicted_power) == ("", "", 0.0)
    hud = ext_module("hud").hud_lines(sc)
    assert len(hud) == 1 and "power budget must be > 0" in hud[0][0] and hud[0][1][1] < 0.5
    props.power_budget = 10.0  # fixed: playback resumes
    sc.frame_set(31)
    assert props.playback_status in ("on target", "blending") and props.active_indices
    sc.camera = None  # no active camera: said, and nothing stale left
    sc.frame_set(32)
    assert props.playback_status.startswith("error: the scene has no active camera")
    assert (props.active_indices, props.predicted_power) == ("", 0.0)


# -- bad input for the operators ----------------------------------------------------------------------------
def _point_at_dead_service() -> None:
    from addon.core.local_service import free_port

    prefs = ext_module("preferences").get()
    prefs.service_mode = "REMOTE"
    prefs.url = f"http://127.0.0.1:{free_port()}"
    prefs.timeout_s = 2


@pytest.fixture
def local_jobs(ext):
    """Jobs on this computer (the default), restored after the test."""
    prefs = ext_module("preferences").get()
    prefs.service_mode, prefs.url = "LOCAL", ""
    yield prefs
    prefs.service_mode = "LOCAL"


def test_optimize_with_service_down_keeps_the_blend_intact(scene, tmp_path) -> None:
    sc = scene
    turning_camera(sc, 12)
    add_cube(sc)
    bpy.ops.render_budget.record_path_animation()
    _load_store(tmp_path)
    store_before = sc.render_budget.store_text.as_string()
    path_before = sc.render_budget.path_text.as_string()
    _point_at_dead_service()
    with pytest.raises(RuntimeError, match=r"no render-budget service.*render-budget serve.*This computer"):
        bpy.ops.render_budget.optimize()
    assert sc.render_budget.store_text.as_string() == store_before
    assert sc.render_budget.path_text.as_string() == path_before
    assert bpy.context.window_manager.render_budget_runtime.job_status.startswith("failed")
    # previews render here with the bundled core whatever the service does
    assert bpy.ops.render_budget.preview(scale=0.25) == {"FINISHED"}


@pytest.mark.parametrize(("url", "message"), [
    ("127.0.0.1:8765", "URL '127.0.0.1:8765' is malformed: it must look like http://host:port"),
    ("render-host:8765", "URL 'render-host:8765' is malformed"),
    ("", "no remote service URL is set"),
    ("http://render-host.example:8765", "needs 'Allow Online Access'"),
])
def test_remote_url_problems_say_what_to_set_up(scene, url, message) -> None:
    turning_camera(scene, 6)
    add_cube(scene)
    prefs = ext_module("preferences").get()
    prefs.service_mode, prefs.url = "REMOTE", url
    assert not bpy.app.online_access
    try:
        with pytest.raises(RuntimeError, match=message):
            bpy.ops.render_budget.optimize()
        with pytest.raises(RuntimeError, match=message):
            bpy.ops.render_budget.service_start()
    finally:
        prefs.service_mode, prefs.url = "LOCAL", ""


def test_the_default_runs_jobs_here_and_needs_no_set_up(ext) -> None:
    prefs = ext_module("preferences").get()
    assert prefs.bl_rna.properties["service_mode"].default == "LOCAL"
    assert prefs.bl_rna.properties["url"].default == ""
    assert bpy.ops.render_budget.service_start() == {"FINISHED"}
    status = bpy.context.window_manager.render_budget_runtime.service_status
    assert status.startswith("this computer: bundled simulator")


@pytest.mark.parametrize(("mode", "field", "value", "message"),
                         [("POWER", "power_budget", 0.0, "power budget must be > 0"),
                          # 0 means "from the path's aspect"; 1..7 passes Blender's limits, not the schema's
                          ("ERROR", "eval_width", 4, r"eval_width must be in \[8, 1024\]")])
def test_optimize_rejects_invalid_settings(scene, mode, field, value, message) -> None:
    turning_camera(scene, 6)
    add_cube(scene)
    _point_at_dead_service()
    props = scene.render_budget
    props.budget_mode = mode
    setattr(props, field, value)
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.render_budget.optimize()
    assert props.store_text is None


def test_optimize_refuses_empty_scene_and_missing_camera(scene) -> None:
    _point_at_dead_service()
    add_camera(scene)
    with pytest.raises(RuntimeError, match="empty scene"):
        bpy.ops.render_budget.optimize()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    add_cube(bpy.context.scene)
    with pytest.raises(RuntimeError, match="no active camera"):
        bpy.ops.render_budget.optimize()


def test_evaluate_without_store_is_reported(scene) -> None:
    turning_camera(scene, 6)
    add_cube(scene)
    _point_at_dead_service()
    with pytest.raises(RuntimeError, match="no Pareto store"):
        bpy.ops.render_budget.evaluate_path(directory=str(Path(sys.prefix)))


def test_hud_text_flags_a_broken_budget(scene, tmp_path) -> None:
    hud = ext_module("hud")
    turning_camera(scene, 6)
    add_cube(scene)
    assert hud.hud_lines(scene) == []  # nothing to show without a store
    bpy.ops.render_budget.record_path_animation()
    _load_store(tmp_path)
    props = scene.render_budget
    props.budget_mode, props.power_budget = "POWER", 10.0
    scene.frame_set(2)
    lines = hud.hud_lines(scene)
    assert "W" in lines[0][0] and lines[0][1] == (1.0, 1.0, 1.0, 1.0)
    assert lines[0][0].endswith("[size unknown]")  # a store that does not say where it was priced
    assert props.active_settings in lines[1][0]
    props.power_budget = 0.5  # below every frontier point: infeasible, shown in red
    scene.frame_set(3)
    lines = hud.hud_lines(scene)
    assert lines[0][1][1] < 0.5 and "budget cannot be met" in lines[-1][0].split("; ")


def test_the_hud_and_the_summary_say_which_display_the_figures_hold_for(scene, tmp_path) -> None:
    """A store priced for a 160x90 display in a scene that renders 320x180: the HUD, the panel's summary
    and batch playback's CSV name the display beside every predicted figure, and the render size that
    differs from it."""
    hud = ext_module("hud")
    turning_camera(scene, 6)
    add_cube(scene)
    bpy.ops.render_budget.record_path_animation()
    store = synthetic_store()
    store.meta.update(figures_resolution=[160, 90], display_pricing="tiles:ssim")
    f = tmp_path / "store.json"
    f.write_text(store.to_json())
    assert bpy.ops.render_budget.load_store(filepath=str(f)) == {"FINISHED"}
    props = scene.render_budget
    props.budget_mode, props.power_budget = "POWER", 10.0
    scene.frame_set(2)
    assert hud.hud_lines(scene)[0][0].endswith("[160x90, not 320x180]")
    assert props.summary.endswith("figures for a 160x90 display, not this scene's 320x180")
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    assert hud.hud_lines(scene)[0][0].endswith("[160x90]")


class _Labels:
    """A stand-in for a panel's UILayout that keeps the labels its draw() writes (props are ignored)."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def box(self) -> _Labels:
        return self

    row = column = box

    def label(self, text: str = "", icon: str = "NONE") -> None:
        self.lines.append((text, icon))

    def prop(self, *_args: object, **_kwargs: object) -> None:
        pass

    def flags(self) -> list[str]:
        """The error labels, each with the lines it wraps onto joined again."""
        out: list[str] = []
        for text, icon in self.lines:
            if icon == "ERROR":
                out.append(text)
            elif icon == "BLANK1" and out:
                out[-1] += " " + text
        return out


def test_hud_panels_and_engine_flag_a_frame_in_one_wording(scene, tmp_path) -> None:
    """A frame with the camera outside the store's space under a budget nothing meets: the HUD (short
    forms), the sidebar panel, the render engine's Budget panel and the engine's frame note (long forms)
    all say so in the words of ``playback_logic.FRAME_FLAGS``, the HUD's the start of the others'."""
    from types import SimpleNamespace

    from addon.core.playback_logic import FRAME_FLAGS, frame_flags

    hud, panels, render = ext_module("hud"), ext_module("panels"), ext_module("engine.render")
    cam = turning_camera(scene, 6)
    add_cube(scene)
    bpy.ops.render_budget.record_path_animation()
    _load_store(tmp_path)  # its space: the cube -10..10 around the origin
    props = scene.render_budget
    props.budget_mode, props.power_budget, props.filter_period = "POWER", 0.5, 0.0  # below every point
    cam.animation_data_clear()
    cam.location = (50.0, 0.0, 1.0)
    scene.frame_set(2)
    assert props.clamped and props.infeasible and props.playback_status == "on target"
    long = [FRAME_FLAGS["infeasible"][1], FRAME_FLAGS["clamped"][1]]
    assert long == frame_flags(infeasible=True, clamped=True)
    hud_flags = hud.hud_lines(scene)[-1][0].split("; ")
    assert hud_flags == [FRAME_FLAGS["infeasible"][0], FRAME_FLAGS["clamped"][0]], hud_flags
    sidebar = _Labels()
    panels._draw_results(sidebar, props, "size unknown")
    assert sidebar.flags() == long, sidebar.lines
    assert any(text.endswith("(size unknown)") for text, _ in sidebar.lines), sidebar.lines
    budget_panel = _Labels()
    ext_module("engine.panels").RENDER_PT_render_budget_budget.draw(
        SimpleNamespace(split_layout=lambda: budget_panel), SimpleNamespace(scene=scene))
    assert budget_panel.flags() == long, budget_panel.lines
    vfov = ext_module("camera_path").camera_vfov(cam, scene)
    note = render.chooser_for(scene).choose(cam.matrix_world, vfov, 320 / 180, 2 / 24).note.split("; ")
    assert note == long, note
    assert all(text.startswith(short) for text, short in zip(note, hud_flags, strict=True))
    rna = props.bl_rna.properties  # the flags' own property names (tooltips, Python) read the same
    assert [rna[name].name.lower() for name in ("infeasible", "clamped")] == hud_flags


def test_hud_shows_the_frame_rate_the_power_is_drawn_at(scene, tmp_path) -> None:
    """A store with frame times: the HUD says the frame rate the predicted power is drawn at, and flags
    the frames where no setting keeps up with the store's frame rate; an older store shows none."""
    hud = ext_module("hud")
    turning_camera(scene, 6)
    add_cube(scene)
    bpy.ops.render_budget.record_path_animation()
    props = scene.render_budget
    props.budget_mode, props.power_budget = "POWER", 10.0
    _load_store(tmp_path, timed=True)
    scene.frame_set(2)
    lines = hud.hud_lines(scene)
    assert props.predicted_fps == pytest.approx(24.0) and not props.slower_than_fps
    assert "W at 24.0 fps" in lines[0][0] and lines[0][1] == (1.0, 1.0, 1.0, 1.0)
    _load_store(tmp_path, slow=True)  # every setting takes >= 60 ms: below 24 fps
    scene.frame_set(3)
    lines = hud.hud_lines(scene)
    assert props.slower_than_fps and props.predicted_fps == pytest.approx(10.0)  # max quality: 0.1 s a frame
    assert "W at 10.0 fps" in lines[0][0]
    assert any("keeps up" in text for text, _ in lines)
    _load_store(tmp_path)  # a store before frame times: no frame rate shown, nothing flagged
    scene.frame_set(4)
    lines = hud.hud_lines(scene)
    assert props.predicted_fps == 0.0 and not props.slower_than_fps and " fps" not in lines[0][0]


def test_playback_hud_and_engine_look_up_under_the_scene_query_options(scene, tmp_path) -> None:
    """The scene's Frame rate and Priority reach every lookup: playback gives what the pure driver gives
    under them (target written for the HUD), the HUD says "budget first" and why a frame misses the rate,
    the render engine's chooser and the panel summary read the same options, a target the store cannot
    answer is a playback error, and a file saved with them keeps them."""
    from addon.core.playback_logic import PlaybackDriver, missed_rate_text

    hud, render = ext_module("hud"), ext_module("engine.render")
    cam = turning_camera(scene, 6)
    add_cube(scene)
    bpy.ops.render_budget.record_path_animation()
    props = scene.render_budget
    props.budget_mode, props.power_budget, props.filter_period = "POWER", 10.0, 0.0

    def load(**kind: bool) -> ParetoStoreType:
        store = synthetic_store(**kind)
        store.meta["static_power_w"] = 0.2  # another frame rate can be asked for
        f = tmp_path / "store.json"
        f.write_text(store.to_json())
        assert bpy.ops.render_budget.load_store(filepath=str(f)) == {"FINISHED"}
        return store

    store = load(timed=True)
    scene.frame_set(2)
    assert props.target_fps == pytest.approx(24.0) and "budget first" not in hud.hud_lines(scene)[0][0]
    props.fps, props.priority, props.error_margin, props.power_margin = 12.0, "budget", 0.001, 0.05
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "query.blend"))
    scene.frame_set(3)
    vfov = ext_module("camera_path").camera_vfov(cam, scene)
    want = PlaybackDriver(store, 0.0).step(np.array(cam.matrix_world), vfov, 320 / 180, 2 / 24, "POWER", 10.0,
                                           fps=12.0, priority="budget", error_margin=0.001,
                                           power_margin=0.05)
    assert want.priority == "budget" and props.target_fps == pytest.approx(12.0)
    assert props.active_indices == " ".join(map(str, want.active_indices))
    assert props.predicted_power == pytest.approx(want.predicted_power_w, rel=1e-6)
    assert "budget first" in hud.hud_lines(scene)[0][0]
    assert render.chooser_for(scene).query == pytest.approx({"fps": 12.0, "priority": "budget",
                                                             "error_margin": 0.001,
                                                             "power_margin": 0.05})
    load(timed=True)  # loading a store summarises it under the scene's query options
    assert "budget first" in props.summary and "of 12 fps" in props.summary
    props.fps = 0.0  # the store's own 24 fps, which no setting of a slow store keeps up with
    load(slow=True)
    scene.frame_set(4)
    flags = hud.hud_lines(scene)[-1][0].split("; ")
    missed = missed_rate_text(24.0, "budget")  # one wording: the HUD's, the panel's and the engine's
    assert props.slower_than_fps and missed in flags, flags
    note = render.chooser_for(scene).choose(cam.matrix_world, vfov, 320 / 180, 4 / 24).note
    assert missed in note.split("; "), note
    props.priority = "frame_rate"
    scene.frame_set(5)
    assert missed_rate_text(24.0, "frame_rate") in hud.hud_lines(scene)[-1][0].split("; ")
    assert missed_rate_text(24.0, "frame_rate") in render.chooser_for(scene).choose(
        cam.matrix_world, vfov, 320 / 180, 5 / 24).note.split("; ")
    props.fps = 50.0
    _load_store(tmp_path, timed=True)  # no static power: only its own frame rate (loaded, and it says so)
    assert "lookup options unusable" in props.summary and "static power" in props.summary
    scene.frame_set(2)
    assert props.playback_status.startswith("error") and "static power" in props.playback_status
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "query.blend"))
    again = bpy.context.scene.render_budget
    assert (again.fps, again.priority) == (12.0, "budget") and again.error_margin == pytest.approx(0.001)
    assert again.power_margin == pytest.approx(0.05)


def _load_store_at_24fps(scene, tmp_path):
    """A recorded 6-frame path and a loaded timed store at its own 24 fps that can be asked for another
    frame rate (static power known); the scene's render-budget properties."""
    turning_camera(scene, 6)
    add_cube(scene)
    bpy.ops.render_budget.record_path_animation()
    store = synthetic_store(timed=True)
    store.meta["static_power_w"] = 0.2  # another frame rate can be asked for
    f = tmp_path / "store.json"
    f.write_text(store.to_json())
    assert bpy.ops.render_budget.load_store(filepath=str(f)) == {"FINISHED"}
    return scene.render_budget


def test_batch_playback_sets_a_saved_frame_rate_back_to_the_stores_own(scene, tmp_path) -> None:
    """A .blend saved with Frame rate 12: batch playback keeps it when --fps is left out and plays at the
    store's own 24 fps with ``--fps store`` (the command line a pipeline runs, in its own process)."""
    import csv
    import os
    import subprocess

    from tests.addon_support import REPO_ROOT

    props = _load_store_at_24fps(scene, tmp_path)
    props.budget_mode, props.power_budget, props.fps = "POWER", 10.0, 12.0
    blend = tmp_path / "saved_at_12fps.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    for extra, want in (((), 12.0), (("--fps", "store"), 24.0)):
        out = tmp_path / "played.csv"
        proc = subprocess.run([sys.executable, "-m", "addon.batch", "--blend", str(blend), "playback",
                               "--out", str(out), *extra], cwd=REPO_ROOT, capture_output=True, text=True,
                              env=env, timeout=600, check=False)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        rows = list(csv.DictReader(out.open(newline="")))
        assert len(rows) == 6 and {float(r["fps_target"]) for r in rows} == {want}, extra


def test_preview_prices_playbacks_settings_at_the_frame_rate_their_lookup_used(scene, tmp_path) -> None:
    """Preview Frame with the active settings prices them at the rate playback's lookup chose them for
    (the store's own 24 fps, or the Frame rate option's 12), as the render engine does, not at the
    scene's 30 fps; at maximum quality (no lookup) at the scene's."""
    import json

    ops_preview = ext_module("ops_preview")
    scene.render.fps = 30
    props = _load_store_at_24fps(scene, tmp_path)
    props.budget_mode, props.power_budget = "POWER", 10.0
    for frame, fps, want in ((2, 0.0, 24.0), (3, 12.0, 12.0)):
        props.fps = fps
        scene.frame_set(frame)
        assert props.target_fps == pytest.approx(want)
        assert ops_preview.prepare(scene, use_active=True, scale=0.1).fps == pytest.approx(want)
    image = ops_preview.render_preview(scene, use_active=True, scale=0.1)
    assert json.loads(image["render_budget"])["energy"]["fps"] == pytest.approx(12.0)
    assert ops_preview.prepare(scene, use_active=False, scale=0.1).fps == pytest.approx(30.0)


def test_an_infeasible_budget_says_it_cannot_be_met_and_what_the_cheapest_setting_costs(scene, tmp_path
                                                                                       ) -> None:
    turning_camera(scene, 12)
    add_cube(scene)
    bpy.ops.render_budget.record_path_animation()
    props = scene.render_budget
    props.budget_mode, props.power_budget = "POWER", 0.05  # the synthetic store's cheapest point: 1.35 W+
    _load_store(tmp_path)
    assert "cannot be met on every frame of the path" in props.summary
    assert "cheapest setting costs" in props.summary and "saved" not in props.summary
    from service.camera_path import CameraPath

    store = synthetic_store()
    frames = CameraPath.from_json(props.path_text.as_string()).frames
    cheapest = [store.lookup(f.position, matrix=f.matrix_world, fov=f.vfov, aspect=f.aspect,
                             power_budget=0.05) for f in frames]
    assert all(hit.infeasible for hit in cheapest)
    lo, hi = min(h.power_w for h in cheapest), max(h.power_w for h in cheapest)
    assert f"costs {lo:.3f}-{hi:.3f} W there (raise the budget to at least {hi:.3f} W)" in props.summary
    props.power_budget = 10.0  # a budget the store meets: the usual summary
    _load_store(tmp_path)
    assert "saved" in props.summary and "cannot be met" not in props.summary


def test_panel_and_preferences_refer_to_existing_properties(ext) -> None:
    """Drawing needs a window; check statically that every property the UI draws exists."""
    import ast

    scene_group = bpy.types.Scene.bl_rna.properties["render_budget"].fixed_type
    scene_props = set(scene_group.properties.keys())
    item_props = set(scene_group.properties["parameters"].fixed_type.properties.keys())  # the list's rows
    wm_rna = bpy.types.WindowManager.bl_rna
    runtime = set(wm_rna.properties["render_budget_runtime"].fixed_type.properties.keys())
    from service.options import PUBLIC

    assert {o.name for o in PUBLIC} <= scene_props  # the panel draws every optimiser option by name
    src = Path(ext.__file__).parent / "panels.py"
    for node in ast.walk(ast.parse(src.read_text())):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") in {"prop", "prop_search"}:
            owner = getattr(node.args[0], "id", "")
            name = node.args[1]
            choices = [name.body, name.orelse] if isinstance(name, ast.IfExp) else [name]
            names = [c.value for c in choices if isinstance(c, ast.Constant)]  # options: drawn by name
            for n in names:
                assert n in (scene_props if owner == "props" else runtime | scene_props | item_props), n
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "operator":
            idname = node.args[0].value
            getattr(getattr(bpy.ops, idname.split(".")[0]), idname.split(".")[1]).get_rna_type()


def test_the_one_export_carries_the_extras_the_simulator_reads(scene, tmp_path) -> None:
    """The one glTF export (the scene generators' scene.glb) keeps custom properties as glTF extras: the
    environment colour and a light's radius reach sim_core's loader; the add-on's own settings group,
    store included, stays out of the file."""
    from sim_core.loaders import load_gltf

    turning_camera(scene, 6)
    add_cube(scene)
    bpy.ops.render_budget.record_path_animation()
    scene["render_budget_environment"] = [0.2, 0.3, 0.4]
    lamp = bpy.data.lights.new("Lamp", "POINT")
    lamp["render_budget_radius"] = 0.25
    scene.collection.objects.link(bpy.data.objects.new("Lamp", lamp))
    _load_store(tmp_path)
    glb = ext_module("scene_export").export_glb(scene, tmp_path / "scene.glb")
    data = load_gltf(glb)
    assert np.allclose(data.environment, [0.2, 0.3, 0.4])
    assert [light.radius for light in data.lights] == [pytest.approx(0.25)]
    assert b"render_budget_store" not in glb.read_bytes() and b"frontiers" not in glb.read_bytes()
