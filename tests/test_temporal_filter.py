"""The temporal filter along the frontier (service.store.temporal): every shown setting is one the caller
allows (a frontier point that keeps the budget), the target is reached within T, nothing pops at a
target change; the playback driver on a real optimised store; the lookup's frame-rate target."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sim_core
from addon.core.playback_logic import PlaybackDriver
from service.camera_path import CameraPath
from service.eval_cache import EvalCache
from service.executors import InProcessExecutor
from service.optimize import OptimizeConfig, optimize_path
from service.params import default_space
from service.store import TemporalFilter, pack_indices, unpack_indices
from service.store.frame_rate import power_at_rate
from service.store.temporal import blend
from tests.addon_support import synthetic_store
from tests.api_support import teapot_scene_file

N_PARAMS = 3
setting = st.tuples(*[st.integers(0, 5)] * N_PARAMS)


@st.composite
def frontier_frames(draw: st.DrawFn) -> tuple[float, float, list[tuple[float, dict, tuple]]]:
    """A power budget, a period and a sequence of frames: (time, {setting: power} of that frame's
    frontier, target), the target being the frontier's least-error point within the budget when any is
    (power ascending = error descending along a frontier: the last point within the budget), else the
    cheapest."""
    budget = draw(st.floats(0.5, 3.0))
    period = draw(st.sampled_from([0.5, 1.0, 2.0]))
    frames = []
    t = 0.0
    for _ in range(draw(st.integers(2, 40))):
        t += draw(st.sampled_from([1 / 30, 0.1, 0.4, 1.3]))
        pts = draw(st.lists(setting, min_size=1, max_size=6, unique=True))
        powers = sorted(draw(st.lists(st.floats(0.1, 4.0), min_size=len(pts), max_size=len(pts))))
        frontier = dict(zip(pts, powers, strict=True))
        within = [p for p in pts if frontier[p] <= budget]
        frames.append((t, frontier, within[-1] if within else pts[0]))
    return budget, period, frames


@settings(max_examples=300, deadline=None)
@given(frontier_frames())
def test_every_filtered_setting_keeps_the_power_budget_when_the_target_does(case) -> None:
    budget, period, frames = case
    f = TemporalFilter(period)
    for t, frontier, target in frames:
        allowed = [p for p, w in frontier.items() if w <= budget] or [target]
        shown = f.update(target, t, allowed)
        assert shown in allowed  # a point of this frame's frontier that keeps the budget ...
        if frontier[target] <= budget:
            assert frontier[shown] <= budget  # ... whenever the target does


@settings(max_examples=300, deadline=None)
@given(st.lists(setting, min_size=1, max_size=8, unique=True), setting, st.data(),
       st.sampled_from([0.5, 2.0]))
def test_the_filter_moves_towards_the_target_and_reaches_it_within_t(points, old, data, period) -> None:
    target = data.draw(st.sampled_from(points))
    f = TemporalFilter(period)
    assert f.update(old, 0.0) == old
    # the target changes at t0; the allowed points stay the same over the transition
    t0 = data.draw(st.floats(0.01, 5.0))
    shown = f.update(target, t0, points)
    if old in points:
        assert shown == old  # no pop: the settings on screen stay while they are allowed
    distance = sum(abs(a - b) for a, b in zip(shown, target, strict=True))
    for k in range(1, 31):
        t = t0 + period * k / 30
        shown = f.update(target, t, points)
        now = sum(abs(a - b) for a, b in zip(shown, target, strict=True))
        assert shown in points and now <= distance  # never away from the target
        distance = now
    assert shown == target  # reached after exactly T
    assert f.update(target, t0 + 10 * period, points) == target


@given(setting, setting, st.floats(0.0, 1.0))
def test_without_allowed_points_it_is_eq_8(old, new, a) -> None:
    expect = tuple(math.floor((1 - a) * o + a * n + 0.5) for o, n in zip(old, new, strict=True))
    assert blend(old, new, a) == (tuple(new) if a >= 1 else expect)


def test_allowed_points_must_include_the_target() -> None:
    f = TemporalFilter(1.0)
    with pytest.raises(ValueError):
        f.update((1, 1, 1), 0.0, [(0, 0, 0)])


def test_a_new_target_mid_transition_starts_from_the_shown_setting() -> None:
    pts = [(0, 0, 0), (1, 1, 1), (2, 2, 2), (3, 3, 3)]
    f = TemporalFilter(1.0)
    f.update((0, 0, 0), 0.0, pts)
    assert f.update((3, 3, 3), 0.1, pts) == (0, 0, 0)
    mid = f.update((3, 3, 3), 0.6, pts)
    assert mid in ((1, 1, 1), (2, 2, 2))
    assert f.update((0, 0, 0), 0.7, pts) == mid  # back: from the shown setting, no pop
    assert f.update((0, 0, 0), 1.7, pts) == (0, 0, 0)
    assert f.update((3, 3, 3), 0.2, pts) == (3, 3, 3)  # time backwards (scrubbing): snap


# -- the frame-rate target ----------------------------------------------------------------------------

@given(st.floats(0.1, 5.0), st.floats(0.0, 0.2), st.floats(1.0, 120.0), st.floats(1.0, 120.0))
def test_power_at_rate_is_the_sustained_power(dynamic_j, frame_time, priced_fps, fps) -> None:
    static = 0.25
    priced, _ = sim_core.sustained_power(static, dynamic_j, frame_time, priced_fps)
    want, _ = sim_core.sustained_power(static, dynamic_j, frame_time, fps)
    assert power_at_rate(priced, frame_time, priced_fps, fps, static) == pytest.approx(want, rel=1e-9)


def test_lookup_honours_another_frame_rate() -> None:
    store = synthetic_store(timed=True)  # frame times 0.03, 0.02, 0.01 s kept at its 24 fps
    with pytest.raises(ValueError, match="static power"):
        store.lookup((0, 0, 0), direction=(1, 0, 0), error_budget=0.5, fps=60.0)
    store.meta["static_power_w"] = 0.2
    base = store.lookup((0, 0, 0), direction=(1, 0, 0), error_budget=0.0)
    same = store.lookup((0, 0, 0), direction=(1, 0, 0), error_budget=0.0, fps=24.0)
    assert same == base and base.fps_target == 24.0
    fast = store.lookup((0, 0, 0), direction=(1, 0, 0), error_budget=0.0, fps=60.0)
    # at 60 fps (16.7 ms) only the 10 ms setting keeps up: chosen although it misses the error budget
    assert fast.meets_fps is True and fast.fps == 60.0 and fast.fps_target == 60.0 and fast.infeasible
    assert fast.frame_time_s == pytest.approx(0.01, rel=1e-3)
    fr = store.frontier(fast.corner, fast.view)
    k = int(np.flatnonzero(fr.packed == fast.packed)[0])
    energy = (float(fr.power_w[k]) - 0.2) / 24.0
    want = sim_core.sustained_power(0.2, energy, float(fr.frame_time_s[k]), 60.0)[0]
    assert fast.power_w == pytest.approx(want, rel=1e-9)
    slow = store.lookup((0, 0, 0), direction=(1, 0, 0), power_budget=10.0, fps=200.0)
    assert slow.meets_fps is False and slow.fps < 200.0  # nothing keeps up with 200 fps: marked
    with pytest.raises(ValueError, match="fps"):
        store.lookup((0, 0, 0), direction=(1, 0, 0), error_budget=0.0, fps=math.nan)
    with pytest.raises(ValueError, match="fps"):
        store.lookup((0, 0, 0), direction=(1, 0, 0), error_budget=0.0, fps=0.0)


def test_budget_points_are_the_frontier_points_within_the_budget() -> None:
    store = synthetic_store()
    hit = store.lookup((0, 0, 0), direction=(0, 1, 0), power_budget=3.0)
    fr = store.frontier(hit.corner, hit.view)
    want = [unpack_indices(int(p), store.n_params) for p, w in zip(fr.packed, fr.power_w, strict=True)
            if w <= 3.0]
    got = store.budget_points(hit)
    assert [p.indices for p in got] == want and hit.indices in want
    assert all(p.power_w <= 3.0 for p in got)
    nothing = store.lookup((0, 0, 0), direction=(0, 1, 0), power_budget=0.01)
    assert nothing.infeasible and [p.indices for p in store.budget_points(nothing)] == [nothing.indices]


# -- a real store ---------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def real_store(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("filter")
    scene = sim_core.Scene.from_gltf(str(teapot_scene_file(d)))
    ang = np.linspace(-1.2, 1.6, 40)
    pos = [(6.0 * np.sin(a), -6.0 * np.cos(a), 1.5 + 1.5 * np.sin(3 * a)) for a in ang]
    dirs = [(-x, -y, 0.6 - z) for x, y, z in pos]
    path = CameraPath.from_positions(pos, dirs, vfov=0.7, resolution=(64, 48))
    space = default_space().subset(["sampling", "max_depth", "resolution_scale", "shadow_samples"])
    opts = OptimizeConfig(max_depth=3, population=8, generations=3, exhaustive_limit=0, eval_width=16,
                          eval_height=12, seed=5, view_sampling="path", path_resolution=0.3, guard_frames=1,
                          display_estimator="full")
    return optimize_path(scene, path, space, opts, cache=EvalCache(), executor=InProcessExecutor()), path


@pytest.mark.slow
def test_playback_on_a_real_store_keeps_every_budget_it_can(real_store) -> None:
    """The playback driver (the one the add-on handler, the render engine and the evaluation campaign
    use) along a real store's path, slowed down so transitions overlap: every shown setting is a point of
    its frame's frontier, predicted within the power (error) budget whenever the target is; the target
    holds T after it last changed."""
    store, path = real_store
    assert store.static_power_w is not None and store.frame_times_known
    powers = sorted({float(p) for f in store.frontiers for p in f.power_w})
    errors = sorted({float(e) for f in store.frontiers for e in f.error})
    budgets = [("POWER", powers[len(powers) // 3]), ("POWER", powers[len(powers) // 2]),
               ("ERROR", errors[len(errors) // 2]), ("ERROR", max(1e-4, errors[len(errors) // 4]))]
    transitions = off_frontier_eq8 = 0
    for mode, budget in budgets:
        drv = PlaybackDriver(store, period_s=1.0)
        eq8 = TemporalFilter(1.0)  # the paper's per-index blend, for contrast
        changed_at, last_target = 0.0, None
        for k, f in enumerate(path.frames * 2):
            t = 0.1 * k  # ten frames a second: a transition spans ten frames
            pf = drv.step(f.matrix_world, f.vfov, f.aspect, t, mode, budget)
            hit = store.lookup(f.position, matrix=np.asarray(f.matrix_world), fov=f.vfov, aspect=f.aspect,
                               **({"power_budget": budget} if mode == "POWER" else {"error_budget": budget}))
            assert pf.target_indices == hit.indices
            fr = store.frontier(hit.corner, hit.view)
            off_frontier_eq8 += pack_indices(eq8.update(hit.indices, t)) not in fr.packed.tolist()
            shown = pack_indices(pf.active_indices)
            assert shown in fr.packed.tolist()  # on the frame's frontier: predicted
            j = int(np.flatnonzero(fr.packed == shown)[0])
            assert pf.predicted_power_w == pytest.approx(float(fr.power_w[j]))
            assert pf.predicted_error == pytest.approx(float(fr.error[j]))
            if not hit.infeasible:
                if mode == "POWER":
                    assert pf.predicted_power_w <= budget
                else:
                    assert pf.predicted_error <= budget
            if pf.target_indices != last_target:
                changed_at, last_target = t, pf.target_indices
            transitions += pf.in_transition
            if t - changed_at >= 1.0 - 1e-9:
                assert pf.active_indices == pf.target_indices
    assert transitions > 0  # the path did change targets mid-way ...
    assert off_frontier_eq8 > 0  # ... where Eq. 8 alone shows settings no frontier predicts


@pytest.mark.slow
def test_the_evaluation_shows_what_playback_shows_on_its_sampled_frames(real_store) -> None:
    """The evaluation campaign samples every n-th path frame but its temporal filter must run at
    playback's pace: its settings on a sampled frame equal those of a driver stepped over every frame
    (stepping the filter over the samples alone restarts a transition at nearly every sample)."""
    from addon.core.evaluate_path import filtered_frames

    store, path = real_store
    powers = sorted({float(p) for f in store.frontiers for p in f.power_w})
    budget, step, period = powers[len(powers) // 2], 4, 1.0
    numbers = range(0, len(path), step)
    shown = filtered_frames(store, path, numbers, "POWER", budget, period)
    every, sampled_only = PlaybackDriver(store, period), PlaybackDriver(store, period)
    differs = 0
    for k, f in enumerate(path.frames):
        pf = every.step(f.matrix_world, f.vfov, f.aspect, f.time, "POWER", budget)
        if k % step == 0:
            assert shown[k].active_indices == pf.active_indices
            alone = sampled_only.step(f.matrix_world, f.vfov, f.aspect, f.time, "POWER", budget)
            differs += alone.active_indices != pf.active_indices
    assert sorted(shown) == list(numbers)
    assert differs > 0  # the test path has transitions the sampled-only stepping shows differently
