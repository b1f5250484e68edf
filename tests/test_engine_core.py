"""The render engine's pure logic with the real native core (no bpy): quality settings generated from
the optimiser's space, per-frame settings from a store or the manual ones, a frame's passes and its
Power pass, the animation CSV, the scene cache and the progressive viewport driver."""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sim_core
from addon.core import engine_frame, engine_scene, engine_settings, progressive, viewport
from addon.core.engine_frame import CameraView, RenderCancelled, render_frame
from addon.core.engine_settings import Budget, FrameSettings, SettingsChooser
from addon.core.playback_logic import FRAME_FLAGS, PlaybackDriver, frame_flags, missed_rate_text
from service.params import default_space, renderable_space
from service.store import camera as camera_maths
from tests.addon_support import synthetic_store

CHEAP = engine_settings.manual_indices({"sampling": "1spp", "shadow_samples": "1", "ao_samples": "0",
                                        "max_depth": "1", "env_filter": "off"})


def box(center, half, z0=0.0):
    """Vertices and triangles of an axis-aligned box."""
    c = np.asarray(center, float)
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float) * half + c
    quads = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
    tris = [(a, b, c_) for a, b, c_, d in quads] + [(a, c_, d) for a, b, c_, d in quads]
    return corners, np.array(tris)


def two_boxes(shift: float = 0.0) -> sim_core.SceneData:
    """A ground slab and a box standing on it (two objects, two materials, a point light)."""
    gp, gt = box((0, 0, -0.05), (4.0, 4.0, 0.05))
    bp, bt = box((shift, 0, 0.5), (0.5, 0.5, 0.5))
    pos = np.vstack([gp, bp]).astype(np.float32)
    tri = np.vstack([gt, bt + len(gp)]).astype(np.uint32)
    ids = np.r_[np.zeros(len(gt)), np.ones(len(bt))].astype(np.uint32)
    return sim_core.SceneData(
        positions=pos, triangles=tri, material_ids=ids, object_ids=ids,
        materials=[sim_core.Material(base_color=(0.7, 0.7, 0.7)),
                   sim_core.Material(base_color=(0.8, 0.2, 0.1), roughness=0.3)],
        lights=[sim_core.Light(kind="point", position=(2.0, -2.0, 4.0), intensity=80.0)],
        environment=(0.3, 0.35, 0.4), object_names=["Ground", "Box"])


def look(eye, target=(0.0, 0.0, 0.4)) -> list[list[float]]:
    return camera_maths.look_matrix(eye, np.subtract(target, eye)).tolist()


@pytest.fixture(scope="module")
def scene() -> sim_core.Scene:
    return sim_core.Scene.from_scene_data(two_boxes())


VIEW = CameraView(look((1.0, -4.0, 2.0)), 0.7, 96, 64)


# -- quality settings -------------------------------------------------------------------------------
def test_quality_properties_are_every_value_a_store_may_name() -> None:
    """The manual settings offer every value a job may search (the default search space's among them),
    so the engine renders whatever a store picks."""
    space = renderable_space()
    assert all(set(p.values) <= set(q.values)
               for p, q in zip(default_space().parameters, space.parameters, strict=True))
    props = engine_settings.quality_properties()
    assert [p.name for p in props] == list(space.names)
    for p, prm in zip(props, space.parameters, strict=True):
        assert len(p.items) == len(prm.values) and len({i[0] for i in p.items}) == len(prm.values)
        assert p.default == p.items[prm.max_quality][0]
    picks = {p.name: p.items[0][0] for p in props}  # the first (cheapest) value of every parameter
    assert engine_settings.manual_indices(picks) == tuple(0 for _ in props)
    assert engine_settings.manual_indices({}) == space.max_quality_indices()
    with pytest.raises(ValueError, match="not a value"):
        engine_settings.manual_indices({"max_depth": "9"})


def orbit(n: int, radius: float = 6.0) -> list[list[list[float]]]:
    out = []
    for k in range(n):
        a = 2 * math.pi * k / n
        out.append(look((radius * math.cos(a), radius * math.sin(a), 1.0), (0.0, 0.0, 1.0)))
    return out


def test_store_chooser_steps_like_playback_and_manual_without_a_store() -> None:
    store = synthetic_store()
    store.meta.update(figures_resolution=[640, 360], display_pricing="tiles:ssim")
    budget = Budget("POWER", 3.3)
    chooser = SettingsChooser(CHEAP, store, budget, period_s=0.5)
    reference = PlaybackDriver(synthetic_store(), 0.5)
    seen = set()
    for k, m in enumerate(orbit(24)):
        t = k / 24.0
        got = chooser.choose(m, 0.69, 16 / 9, t)
        want = reference.step(m, 0.69, 16 / 9, t, "POWER", 3.3)
        assert got.source == "store"
        assert got.indices == engine_settings.space().indices_of(want.active_settings)
        assert got.predicted_power_w == want.predicted_power_w and got.predicted_error == want.predicted_error
        assert got.in_transition == want.in_transition
        assert got.predicted_for == "640x360"  # the display the store's predictions hold for
        seen.add(got.indices)
    assert len(seen) > 1  # the store's choice changes around the orbit
    manual = SettingsChooser(CHEAP).choose(orbit(1)[0], 0.69, 16 / 9, 0.0)
    assert manual.source == "manual" and manual.indices == CHEAP and manual.predicted_power_w is None
    assert manual.predicted_for == ""
    assert SettingsChooser(CHEAP, store, None).choose(orbit(1)[0], 0.69, 1.5, 0.0).source == "manual"
    with pytest.raises(ValueError, match="power budget"):
        Budget("POWER", 0.0)


# -- one frame --------------------------------------------------------------------------------------
def test_frame_passes(scene: sim_core.Scene) -> None:
    fs = FrameSettings("manual", CHEAP)
    bands: list[float] = []
    out = render_frame(scene, VIEW, fs, profile="mobile", fps=30.0, object_pass_index=[2, 5],
                       progress=bands.append)
    assert bands and bands[-1] == 1.0 and bands == sorted(bands)
    direct = sim_core.render(scene, VIEW.camera(), fs.render_settings(),
                             cache=sim_core.load_profile("mobile").cache)
    np.testing.assert_array_equal(out.combined[..., :3], direct.image)
    assert np.all(out.combined[..., 3] == 1.0)
    hit = direct.aovs["object_id"] >= 0
    assert hit.any() and (~hit).any()
    depth = out.passes["Depth"][..., 0]
    assert np.all(depth[~hit] == engine_frame.BACKGROUND_DEPTH)
    assert np.all((depth[hit] > 0) & (depth[hit] < 20))
    normal = out.passes["Normal"]
    np.testing.assert_allclose(np.linalg.norm(normal[hit], axis=1), 1.0, atol=1e-3)
    index = out.passes["IndexOB"][..., 0]
    want = np.select([direct.aovs["object_id"] == 0, direct.aovs["object_id"] == 1], [2.0, 5.0], 0.0)
    np.testing.assert_array_equal(index, want)
    assert set(np.unique(out.passes["Sample Kind"])) <= {0.0}  # 1 spp traces every pixel
    report = sim_core.price(direct, "mobile", 30.0, scene=scene)
    assert out.power_w == pytest.approx(report.power_w)
    assert out.passes["Power"].sum() * 1e-6 == pytest.approx(out.dynamic_power_w, rel=1e-5)
    assert out.dynamic_power_w == pytest.approx(report.dynamic_energy_j * report.achieved_fps)
    assert out.achieved_fps == report.achieved_fps and out.power_w <= report.power_full_speed_w
    meta = out.metadata()
    assert meta["render_budget.source"] == "manual" and "max_depth=1" in meta["render_budget.settings"]
    assert float(meta["render_budget.simulated_power_w"]) == pytest.approx(out.power_w, rel=1e-5)
    assert "render_budget.predicted_power_w" not in meta


def test_adaptive_frame_at_reduced_resolution_and_transparent_film(scene: sim_core.Scene) -> None:
    idx = engine_settings.manual_indices({"sampling": "undersample_4x4", "resolution_scale": "0.7",
                                          "shadow_samples": "1", "ao_samples": "0",
                                          "normal_threshold_deg": "45.0"})
    fs = FrameSettings("store", idx, predicted_power_w=1.25, predicted_error=0.012)
    out = render_frame(scene, VIEW, fs, profile="mobile", fps=24.0, transparent=True)
    assert out.render_resolution == (67, 45)
    assert out.combined.shape == (64, 96, 4) and out.passes["Power"].shape == (64, 96, 1)
    kinds = set(np.unique(out.passes["Sample Kind"]).tolist())
    assert {0.0, 1.0} <= kinds <= {0.0, 1.0, 2.0}  # references traced, similar pixels interpolated
    alpha = out.combined[..., 3]
    background = out.passes["Depth"][..., 0] == engine_frame.BACKGROUND_DEPTH
    assert np.all(alpha[background] == 0.0) and np.all(alpha[~background] == 1.0)
    assert np.all(out.combined[background, :3] == 0.0)  # premultiplied
    assert out.passes["Power"].sum() * 1e-6 == pytest.approx(out.dynamic_power_w, rel=1e-5)
    meta = out.metadata()
    assert meta["render_budget.predicted_power_w"] == "1.25"
    assert meta["render_budget.predicted_error"] == "0.012"


def test_the_power_pass_is_hot_where_the_work_is(scene: sim_core.Scene) -> None:
    """Tiles looking at geometry trace shadow rays and walk the BVH; tiles of empty sky do not."""
    fs = FrameSettings("manual", engine_settings.manual_indices({"sampling": "1spp", "ao_samples": "4"}))
    out = render_frame(scene, VIEW, fs, profile="mobile", fps=30.0)
    power = out.passes["Power"][..., 0]
    sky = out.passes["Depth"][..., 0] == engine_frame.BACKGROUND_DEPTH
    assert power[~sky].mean() > 2 * power[sky].mean() > 0  # sky pixels share tiles with geometry too


def test_a_window_of_a_frame_keeps_its_share(scene: sim_core.Scene) -> None:
    """An off-centre camera renders a window of a larger centred frame: images cropped, the power its
    share of the frame's (the Power pass over the window)."""
    out = render_frame(scene, VIEW, FrameSettings("manual", CHEAP), profile="mobile", fps=30.0)
    win = out.window(10, 4, 50, 40)
    assert win.combined.shape == (40, 50, 4) and all(p.shape[:2] == (40, 50) for p in win.passes.values())
    np.testing.assert_array_equal(win.passes["Depth"], out.passes["Depth"][4:44, 10:60])
    assert win.passes["Power"].sum() * 1e-6 == pytest.approx(win.dynamic_power_w, rel=1e-6)
    assert 0 < win.dynamic_power_w < out.dynamic_power_w
    assert win.power_w - win.dynamic_power_w == pytest.approx(out.power_w - out.dynamic_power_w)
    assert win.frame_time_s < out.frame_time_s and "window" in win.metadata()["render_budget.note"]
    with pytest.raises(ValueError, match="outside"):
        out.window(60, 0, 50, 10)


def test_a_frame_that_misses_its_frame_rate_draws_power_at_its_own(scene: sim_core.Scene) -> None:
    """Asked for more frames a second than the GPU delivers, a frame's power is the full-speed power at
    1 / frame time (never E x fps), the Power pass sums to it, the metadata and the viewport's status
    say the rate reached; a window of it, faster, may keep up again and is priced at its own rate."""
    prof = sim_core.load_profile("mobile")
    slow = render_frame(scene, VIEW, FrameSettings("manual", CHEAP), profile="mobile", fps=30.0)
    fps = 3.0 / slow.frame_time_s  # three times what this frame can do
    out = render_frame(scene, VIEW, FrameSettings("manual", CHEAP), profile="mobile", fps=fps)
    assert not out.deadline_met and out.achieved_fps == pytest.approx(1.0 / out.frame_time_s)
    energy = out.dynamic_power_w / out.achieved_fps
    assert out.power_w == pytest.approx(prof.static_power_w + energy / out.frame_time_s)
    assert out.dynamic_power_w < energy * fps  # E x fps would be three times as much
    assert out.passes["Power"].sum() * 1e-6 == pytest.approx(out.dynamic_power_w, rel=1e-5)
    assert float(out.metadata()["render_budget.achieved_fps"]) == pytest.approx(out.achieved_fps, rel=1e-3)
    win = out.window(0, 0, VIEW.width // 4, VIEW.height // 4)
    assert win.passes["Power"].sum() * 1e-6 == pytest.approx(win.dynamic_power_w, rel=1e-5)
    assert win.achieved_fps == (fps if win.deadline_met else pytest.approx(1.0 / win.frame_time_s))
    assert win.power_w <= out.power_w


def test_without_passes_the_image_and_power_are_the_same(scene: sim_core.Scene) -> None:
    """The viewport skips the passes (no per-tile pricing): the same image and frame power, and a window
    (which needs the Power pass for its share) is refused rather than guessed."""
    fs = FrameSettings("manual", CHEAP)
    full = render_frame(scene, VIEW, fs, profile="mobile", fps=30.0)
    bare = render_frame(scene, VIEW, fs, profile="mobile", fps=30.0, passes=False)
    assert bare.passes == {}
    np.testing.assert_array_equal(bare.combined, full.combined)
    assert (bare.power_w, bare.dynamic_power_w, bare.frame_time_s) == (
        full.power_w, full.dynamic_power_w, full.frame_time_s)
    with pytest.raises(ValueError, match="Power pass"):
        bare.window(10, 4, 50, 40)


def test_measured_error_is_the_optimisers(scene: sim_core.Scene) -> None:
    """Measure Error renders the maximum-quality frame and measures this frame against it exactly as the
    optimiser's evaluation does (same renders, same metric pipeline)."""
    from service.evaluation import CameraSpec, evaluate

    idx = engine_settings.manual_indices({"sampling": "undersample_4x4", "shadow_samples": "1",
                                          "ao_samples": "0", "max_depth": "1"})
    bands: list[float] = []
    out = render_frame(scene, VIEW, FrameSettings("manual", idx), profile="mobile", fps=30.0,
                       measure_error="ssim", progress=bands.append)
    cam = VIEW.camera()
    spec = CameraSpec(tuple(cam.position), tuple(cam.forward), tuple(cam.up), VIEW.vfov, VIEW.width,
                      VIEW.height)
    want = evaluate(scene, spec, idx, engine_settings.space(), profile="mobile", fps=30.0, metric="ssim")
    assert 0 < out.measured_error == pytest.approx(want.error, abs=1e-12)
    assert out.metadata()["render_budget.measured_error"] == f"{out.measured_error:.6g}"
    assert bands == sorted(bands) and bands[-1] == 1.0 and any(0.45 < b <= 0.5 for b in bands)
    top = render_frame(scene, VIEW, FrameSettings("manual", engine_settings.space().max_quality_indices()),
                       profile="mobile", fps=30.0, measure_error="ssim")
    assert top.measured_error == 0.0
    plain = render_frame(scene, VIEW, FrameSettings("manual", idx), profile="mobile", fps=30.0)
    assert plain.measured_error is None


def test_cancel_between_bands(scene: sim_core.Scene) -> None:
    with pytest.raises(RenderCancelled):
        render_frame(scene, VIEW, FrameSettings("manual", CHEAP), profile="mobile", fps=30.0,
                     should_cancel=lambda: True)
    with pytest.raises(ValueError, match="fps"):
        render_frame(scene, VIEW, FrameSettings("manual", CHEAP), profile="mobile", fps=math.nan)


def test_tiles_priced_one_by_one_sum_to_the_frame(scene: sim_core.Scene) -> None:
    """The tracer's per-tile counters and comparator histograms sum to the frame's, and the energy model
    is linear in them: the tiles' energies add up to the frame's dynamic energy, block by block."""
    settings = engine_settings.space().to_settings(engine_settings.manual_indices(
        {"sampling": "undersample_2x2", "ao_samples": "4", "shadow_samples": "4"}))
    prof = sim_core.load_profile("mobile")
    result = sim_core.render(scene, VIEW.camera(), settings, cache=prof.cache)
    for name in sim_core.COUNTER_NAMES:
        assert sum(t["counters"][name] for t in result.tile_stats) == result.counters[name], name
    np.testing.assert_array_equal(sum(t["comparator_histogram"] for t in result.tile_stats),
                                  result.comparator_histogram)
    frame = sim_core.price(result, prof, 30.0, scene=scene)
    tiles = engine_frame.tile_energy(result.tile_stats, prof, 30.0, settings, scene)
    assert np.all(tiles >= 0) and tiles.sum() == pytest.approx(frame.dynamic_energy_j, rel=1e-9)
    # all tiles priced at once equal each tile priced alone through price() (the previous computation)
    for style in ("sync", "async"):
        p = dataclasses.replace(prof, comparator_style=style)
        one_by_one = [sim_core.price(SimpleNamespace(counters=t["counters"], settings=settings,
                                                     comparator_histogram=t["comparator_histogram"]),
                                     p, 30.0, scene=scene).dynamic_energy_j for t in result.tile_stats]
        np.testing.assert_allclose(engine_frame.tile_energy(result.tile_stats, p, 30.0, settings, scene),
                                   one_by_one, rtol=1e-12, atol=0)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.integers(1, 5), st.integers(1, 90), st.integers(1, 90),
       st.data())
def test_the_power_pass_keeps_the_total_at_any_scale(rw, rh, ts, w, h, data) -> None:
    """Tiles partition the output image at any scale, so the Power pass sums to the tiles' power."""
    tiles = [{"x0": x, "y0": y, "width": min(ts, rw - x), "height": min(ts, rh - y)}
             for y in range(0, rh, ts) for x in range(0, rw, ts)]
    e = np.array(data.draw(st.lists(st.floats(0, 1e-3), min_size=len(tiles), max_size=len(tiles))))
    w, h = max(w, rw), max(h, rh)  # the output is never smaller than what was traced
    power = engine_frame.power_pass(tiles, e, 30.0, (rw, rh), (w, h))
    assert power.shape == (h, w) and np.all(power >= 0)
    assert power.sum(dtype=np.float64) == pytest.approx(e.sum() * 30.0 * 1e6, rel=1e-5, abs=1e-9)


def test_animation_csv(tmp_path, scene: sim_core.Scene) -> None:
    log = engine_frame.AnimationLog(tmp_path / "out" / "shot_render_budget.csv")
    fs = FrameSettings("store", CHEAP, predicted_power_w=0.9, predicted_error=0.01, target_indices=CHEAP)
    out = render_frame(scene, VIEW, fs, profile="mobile", fps=30.0)
    log.add(7, 0.25, out)
    missed = dataclasses.replace(fs, fps_target=30.0, meets_fps=False, priority="budget")
    log.add(8, 0.3, render_frame(scene, VIEW, missed, profile="mobile", fps=30.0))
    log.add(9, 0.35, render_frame(scene, VIEW, FrameSettings("manual", CHEAP), profile="mobile", fps=30.0))
    log.close()
    import csv

    rows = list(csv.DictReader((tmp_path / "out" / "shot_render_budget.csv").open()))
    assert len(rows) == 3 and rows[0]["frame"] == "7" and rows[0]["source"] == "store"
    # the lookup's target and priority, and a frame whose settings miss the rate
    assert (rows[1]["fps_target"], rows[1]["meets_fps"], rows[1]["priority"]) == ("30", "0", "budget")
    assert (rows[2]["fps_target"], rows[2]["meets_fps"], rows[2]["priority"]) == ("", "", "")
    assert rows[0]["max_depth"] == "1" and rows[0]["sampling"] == "1spp"
    assert float(rows[0]["simulated_power_w"]) == pytest.approx(out.power_w, rel=1e-5)
    assert rows[0]["predicted_error"] == "0.01" and rows[0]["in_transition"] == "0"


def test_a_frames_note_flags_it_in_the_words_of_the_hud_and_the_panels() -> None:
    """The engine's frame note (image metadata) says what is flagged on the frame in the one wording of
    the HUD and the panels (``frame_flags``): a camera outside the store's space under a budget nothing
    meets, and the temporal filter blending towards a new target; a frame on target within its budget
    says nothing."""
    store = synthetic_store()  # root cube -10..10; the cheapest setting costs 1.35 W or more
    outside = SettingsChooser(CHEAP, store, Budget("POWER", 0.5)).choose(look((50.0, 0.0, 1.0)), 0.69, 16 / 9,
                                                                         0.0)
    assert outside.clamped and outside.infeasible and not outside.in_transition
    assert outside.note.split("; ") == [FRAME_FLAGS["infeasible"][1], FRAME_FLAGS["clamped"][1]]
    chooser = SettingsChooser(CHEAP, store, Budget("ERROR", 0.01), period_s=1.0)
    eyes = [(3.0, 0.0, 0.4), (0.0, 3.0, 0.4), (-3.0, 0.0, 0.4), (0.0, -3.0, 0.4), (0.0, 0.1, 3.0)] * 3
    frames = [chooser.choose(look(eye), 0.69, 16 / 9, k / 24) for k, eye in enumerate(eyes)]
    assert any(f.in_transition for f in frames) and not all(f.in_transition for f in frames)
    for f in frames:
        assert not (f.clamped or f.infeasible)
        assert f.note == "; ".join(frame_flags(in_transition=f.in_transition)), f.note
    assert FRAME_FLAGS["in_transition"][1] in {f.note for f in frames}


def test_store_chooser_looks_up_under_the_query_options() -> None:
    """The engine's animation renders use the scene's query options: the same frames as the playback
    driver under them, each frame saying its target and priority (and, in its note, a missed rate)."""
    store = synthetic_store(timed=True, slow=True)  # no setting keeps up with the store's 24 fps
    store.meta["static_power_w"] = 0.2
    query = {"fps": 12.0, "priority": "budget"}
    chooser = SettingsChooser(CHEAP, store, Budget("POWER", 3.3), period_s=0.5, query=query)
    reference = PlaybackDriver(store, 0.5)
    for k, m in enumerate(orbit(6)):
        got = chooser.choose(m, 0.69, 16 / 9, k / 24)
        want = reference.step(m, 0.69, 16 / 9, k / 24, "POWER", 3.3, **query)
        assert got.indices == engine_settings.space().indices_of(want.active_settings)
        assert (got.priority, got.fps_target, got.meets_fps) == ("budget", 12.0, want.meets_fps)
    slow = SettingsChooser(CHEAP, store, Budget("POWER", 3.3), query={"priority": "budget"})
    frame = slow.choose(orbit(1)[0], 0.69, 16 / 9, 0.0)
    assert frame.fps_target == 24.0 and frame.meets_fps is False
    assert missed_rate_text(24.0, "budget") in frame.note.split("; ")  # the HUD's and the panel's words
    assert frame.pricing_fps(30.0) == 24.0  # priced at the rate it was looked up for, not the scene's
    assert SettingsChooser(CHEAP, store, Budget("POWER", 3.3), query=query).choose(
        orbit(1)[0], 0.69, 16 / 9, 0.0).pricing_fps(30.0) == 12.0
    assert SettingsChooser(CHEAP, store).manual_settings().pricing_fps(30.0) == 30.0  # manual: the scene's
    assert engine_settings.pricing_fps(12.0, 30.0) == 12.0 and engine_settings.pricing_fps(None, 30.0) == 30.0
    assert SettingsChooser(CHEAP, store, Budget("POWER", 3.3)).choose(orbit(1)[0], 0.69, 16 / 9, 0.0
                                                                       ).priority == "frame_rate"
    with pytest.raises(ValueError, match="priority must be one of"):
        SettingsChooser(CHEAP, store, Budget("POWER", 3.3), query={"priority": "speed"})
    with pytest.raises(ValueError, match="static power"):  # a target the store cannot answer: up front
        SettingsChooser(CHEAP, synthetic_store(timed=True), Budget("POWER", 3.3), query={"fps": 60.0})
    assert SettingsChooser(CHEAP).manual_settings().priority == ""


# -- camera window -----------------------------------------------------------------------------------
def perspective(sx: float, sy: float, a: float, b: float) -> list[list[float]]:
    return [[sx, 0, a, 0], [0, sy, b, 0], [0, 0, -1.0002, -0.2], [0, 0, -1, 0]]


@pytest.mark.parametrize(("a", "b"), [(0.0, 0.0), (0.3, 0.0), (-0.5, 0.2), (0.1, -0.7)])
def test_projection_window_traces_the_projections_rays(a: float, b: float) -> None:
    width, height = 160, 90
    sy = 1.8
    sx = sy * height / width  # square pixels
    vfov, fw, fh, x0, y0 = camera_maths.projection_window(perspective(sx, sy, a, b), width, height)
    th = math.tan(vfov / 2)
    for px, py in ((0.5, 0.5), (width - 0.5, 17.5), (80.0, height - 0.5)):
        ndc_x, ndc_y = 2 * px / width - 1, 1 - 2 * py / height
        want = ((ndc_x + a) / sx, (ndc_y + b) / sy)  # tangent-space direction of the projection's ray
        fx, fy = px + x0, py + y0  # the same pixel in the centred frame
        got = ((2 * fx / fw - 1) * th * fw / fh, (1 - 2 * fy / fh) * th)
        assert got == pytest.approx(want, abs=2.5 / (sy * height))  # within a pixel or so of rounding
    assert x0 + width <= fw and y0 + height <= fh
    with pytest.raises(ValueError, match="orthographic"):
        camera_maths.projection_window([[0.1, 0, 0, 0], [0, 0.1, 0, 0], [0, 0, -0.01, 0], [0, 0, 0, 1]],
                                       width, height)


# -- scene between frames ---------------------------------------------------------------------------
def test_depsgraph_updates_that_need_a_new_scene() -> None:
    U = engine_scene.Update
    assert not engine_scene.needs_translation([])
    assert not engine_scene.needs_translation([U("SCENE"), U("OBJECT", "CAMERA", transform=True),
                                               U("CAMERA"), U("ACTION"), U("OBJECT", "MESH")])
    for u in (U("OBJECT", "MESH", transform=True), U("OBJECT", "MESH", geometry=True), U("MESH"),
              U("MATERIAL"), U("LIGHT"), U("OBJECT", "LIGHT", transform=True), U("WORLD"), U("IMAGE"),
              U("COLLECTION"), U("NODETREE")):
        assert engine_scene.needs_translation([U("SCENE"), u]), u


def test_fingerprint_and_scene_cache() -> None:
    a, b = two_boxes(), two_boxes()
    assert engine_scene.fingerprint(a) == engine_scene.fingerprint(b)
    b.positions[-1, 2] += 1e-3
    assert engine_scene.fingerprint(a) != engine_scene.fingerprint(b)
    c = two_boxes()
    c.materials[1] = sim_core.Material(base_color=(0.8, 0.2, 0.1), roughness=0.31)
    assert engine_scene.fingerprint(a) != engine_scene.fingerprint(c)
    d = two_boxes()  # where it came from and the cameras of the file do not change the render
    d.source = "elsewhere.glb"
    d.cameras = [sim_core.CameraData(np.eye(4), 0.7)]
    assert engine_scene.fingerprint(a) == engine_scene.fingerprint(d)
    cache = engine_scene.SceneCache()
    s1 = cache.scene_for(a)
    assert cache.scene_for(two_boxes()) is s1 and cache.builds == 1
    assert cache.scene_for(b) is not s1 and cache.builds == 2


# -- progressive viewport driver --------------------------------------------------------------------
class Gate:
    """A render function whose levels wait until the test lets them go (band by band)."""

    def __init__(self) -> None:
        self.calls: list[tuple[object, int, int]] = []
        self.release = threading.Semaphore(0)
        self.started = threading.Semaphore(0)

    def __call__(self, payload, w, h, should_stop):
        self.calls.append((payload, w, h))
        self.started.release()
        while not self.release.acquire(timeout=0.005):
            if should_stop():
                raise RenderCancelled
        return np.full((h, w, 4), float(len(self.calls)), np.float32), payload


def wait_for(pred, timeout=10.0):
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.002)


def test_driver_refines_coarse_to_fine() -> None:
    seen: list[progressive.ViewFrame] = []
    gate = Gate()
    drv = progressive.ProgressiveDriver(gate, (0.25, 0.5, 1.0), on_frame=seen.append)
    try:
        assert drv.update(progressive.ViewRequest("a", 64, 40, payload="A"))
        assert not drv.update(progressive.ViewRequest("a", 64, 40, payload="A"))  # same view: nothing to do
        for _ in range(3):
            gate.release.release()
        assert drv.wait_idle()
        assert [(f.level, f.image.shape[:2]) for f in seen] == [(0, (10, 16)), (1, (20, 32)), (2, (40, 64))]
        assert seen[-1].final and drv.latest() is seen[-1] and drv.frames == 3 and drv.cancelled == 0
    finally:
        drv.close()
    assert not drv.alive


def test_restart_cancels_refinement_but_finishes_a_first_level() -> None:
    gate = Gate()
    drv = progressive.ProgressiveDriver(gate, (0.25, 0.5, 1.0))
    try:
        drv.update(progressive.ViewRequest("a", 64, 40, "A"))
        gate.started.acquire(timeout=5)
        drv.update(progressive.ViewRequest("b", 64, 40, "B"))  # during A's first level
        drv.update(progressive.ViewRequest("c", 64, 40, "C"))  # B is skipped: the newest wins
        gate.release.release()  # A's first level completes even though it is stale
        wait_for(lambda: drv.latest() is not None)
        assert drv.latest().key == "a" and drv.latest().level == 0
        gate.started.acquire(timeout=5)  # C's first level
        gate.release.release()
        gate.started.acquire(timeout=5)  # C's second level is in flight ...
        drv.update(progressive.ViewRequest("d", 64, 40, "D"))  # ... and a restart cancels it
        wait_for(lambda: drv.cancelled == 2)  # A's refinement never started, C's second level stopped
        gate.release.release()  # D's three levels
        gate.release.release()
        gate.release.release()
        assert drv.wait_idle()
        keys = [p for p, _, _ in gate.calls]
        assert keys == ["A", "C", "C", "D", "D", "D"] and drv.cancelled == 2
        assert drv.latest().key == "d" and drv.latest().final
    finally:
        drv.close()


def test_close_cancels_in_flight_work() -> None:
    gate = Gate()
    drv = progressive.ProgressiveDriver(gate, (0.5, 1.0))
    drv.update(progressive.ViewRequest("a", 8, 8))
    gate.started.acquire(timeout=5)
    t0 = time.monotonic()
    drv.close()
    assert not drv.alive and time.monotonic() - t0 < 5 and drv.latest() is None and drv.cancelled == 1
    with pytest.raises(RuntimeError, match="closed"):
        drv.update(progressive.ViewRequest("b", 8, 8))


def test_workers_paused_stops_every_worker_and_resumes_their_requests() -> None:
    """Held still while the main thread runs Blender's render operator: the level in flight stops, no
    render starts (not even for a request made meanwhile), and afterwards the stopped request renders."""
    gates = [Gate(), Gate()]
    drivers = [progressive.ProgressiveDriver(g, (1.0,)) for g in gates]
    try:
        drivers[0].update(progressive.ViewRequest("a", 8, 8, "A"))
        gates[0].started.acquire(timeout=5)  # A is rendering
        with progressive.workers_paused():
            assert all(not d._active for d in drivers)  # out of every render
            drivers[1].update(progressive.ViewRequest("b", 8, 8, "B"))
            time.sleep(0.1)
            assert [p for p, _, _ in gates[1].calls] == [] and drivers[0].cancelled == 1
            assert drivers[0].busy and drivers[1].busy  # kept for later
        for g in gates:
            g.release.release()
        assert all(d.wait_idle() for d in drivers)
        assert [p for p, _, _ in gates[0].calls] == ["A", "A"] and drivers[0].latest().key == "a"
        assert drivers[1].latest().key == "b"
        # a worker that does not stop in time: an error, and the workers resume
        late = Gate()
        drivers.append(progressive.ProgressiveDriver(lambda p, w, h, stop: late(p, w, h, lambda: False),
                                                     (1.0,)))
        drivers[2].update(progressive.ViewRequest("c", 8, 8, "C"))
        late.started.acquire(timeout=5)
        with pytest.raises(TimeoutError), progressive.workers_paused(timeout=0.2):
            pass
        late.release.release()
        assert drivers[2].wait_idle() and drivers[2].latest().key == "c" and not progressive._paused()
    finally:
        for d in drivers:
            d.close()


def test_render_errors_are_reported_and_the_driver_recovers() -> None:
    def render(payload, w, h, should_stop):
        if payload == "bad":
            raise ValueError("no geometry")
        return np.zeros((h, w, 4), np.float32), payload

    drv = progressive.ProgressiveDriver(render, (1.0,))
    try:
        drv.update(progressive.ViewRequest(1, 4, 4, "bad"))
        assert drv.wait_idle() and drv.error == "ValueError: no geometry" and drv.latest() is None
        drv.update(progressive.ViewRequest(2, 4, 4, "ok"))
        assert drv.wait_idle() and drv.error is None and drv.latest().info == "ok"
    finally:
        drv.close()
    with pytest.raises(ValueError, match="scales"):
        progressive.ProgressiveDriver(render, (1.0, 0.5))


# -- the viewport with the real tracer ---------------------------------------------------------------
def region_projection(width: int, height: int, vfov: float = 0.8) -> list[list[float]]:
    sy = 1 / math.tan(vfov / 2)
    return perspective(sy * height / width, sy, 0.0, 0.0)


def test_viewport_renders_progressively_and_restarts_on_scene_updates() -> None:
    frames: list[progressive.ViewFrame] = []
    vp = viewport.ViewportRenderer(on_frame=frames.append, scales=(0.25, 1.0), threads=1)
    try:
        fs = FrameSettings("manual", CHEAP)
        with pytest.raises(RuntimeError, match="no scene"):
            vp.show(look((1, -4, 2)), region_projection(80, 48), 80, 48, fs, profile="mobile", fps=30)
        vp.set_scene(two_boxes(), [1, 2])
        assert vp.show(look((1, -4, 2)), region_projection(80, 48), 80, 48, fs, profile="mobile", fps=30)
        assert vp.driver.wait_idle(60)
        assert [f.image.shape for f in frames] == [(12, 20, 4), (48, 80, 4)]
        first = frames[-1]
        assert first.info.source == "manual" and first.info.size == (80, 48)
        power, rate = first.info.power_at(1920 * 1080)  # scaled to the render size, at the rate it reaches
        assert 0 < first.info.dynamic_power_w and power > first.info.static_power_w and 0 < rate <= 30
        # a shaded box in front of the sky: some pixels hit, some do not
        assert first.image[..., :3].std() > 0.01
        # the box moves: the depsgraph reports it, the viewport restarts with the new scene
        vp.set_scene(two_boxes(shift=1.0), [1, 2])
        assert vp.show(look((1, -4, 2)), region_projection(80, 48), 80, 48, fs, profile="mobile", fps=30)
        assert vp.driver.wait_idle(60)
        assert len(frames) == 4 and not np.array_equal(frames[-1].image, first.image)
        assert vp.scenes.builds == 2
        # a camera view with lens shift: the window of a larger centred frame, priced as its share
        sy = 1 / math.tan(0.4)
        shift = perspective(sy * 48 / 80, sy, 0.5, 0.0)
        assert vp.show(look((1, -4, 2)), shift, 80, 48, fs, profile="mobile", fps=30)
        assert vp.driver.wait_idle(60) and vp.error is None
        shifted = frames[-1]
        assert shifted.image.shape == (48, 80, 4) and shifted.final and len(frames) == 6
        assert 0 < shifted.info.dynamic_power_w
        # an orthographic view is refused before anything is queued
        with pytest.raises(ValueError, match="orthographic"):
            vp.show(look((1, -4, 2)), [[0.1, 0, 0, 0], [0, 0.1, 0, 0], [0, 0, -0.01, 0], [0, 0, 0, 1]],
                    80, 48, fs, profile="mobile", fps=30)
    finally:
        vp.close()
    assert not vp.driver.alive


def test_viewport_playback_follows_the_store() -> None:
    """Playing a camera animation: each frame's settings come from the store (through the same driver
    the playback handler uses); the viewport renders every frame it is shown with that frame's
    settings, and the settings it shows change along the path."""
    frames: list[progressive.ViewFrame] = []
    vp = viewport.ViewportRenderer(on_frame=frames.append, scales=(1.0,), threads=1)
    store = synthetic_store()
    playback = PlaybackDriver(store, 0.0)
    try:
        vp.set_scene(two_boxes())
        shown = []
        for k, m in enumerate(orbit(12)):
            frame = playback.step(m, 0.69, 16 / 9, k / 24.0, "POWER", 3.3)
            fs = FrameSettings("store", engine_settings.space().indices_of(frame.active_settings),
                               frame.predicted_power_w, frame.predicted_error, predicted_for="640x360")
            vp.show(m, region_projection(32, 18, 0.69), 32, 18, fs, profile="mobile", fps=24)
            assert vp.driver.wait_idle(60)  # as if playback waited for each frame
            shown.append(fs)
        assert len(frames) == 12
        for f, fs in zip(frames, shown, strict=True):
            assert f.info.settings_text == fs.text() and f.info.predicted_power_w == fs.predicted_power_w
            assert f.info.predicted_for == "640x360"
        assert len({f.info.settings_text for f in frames}) > 1
    finally:
        vp.close()
