"""The temporal filter along the frontier (service.store.temporal): every shown setting is one the caller
allows (a frontier point that keeps the budget), it moves at an even pace in predicted error without
detours through points less accurate than both ends, the target is reached after T, nothing pops at a
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
from service.store.temporal import blend, transition_period
from tests.addon_support import synthetic_store
from tests.api_support import teapot_scene_file

N_PARAMS = 3
setting = st.tuples(*[st.integers(0, 5)] * N_PARAMS)
error = st.integers(0, 1000).map(lambda k: k / 1000)  # predicted errors (1 - SSIM) to three decimals


def _l1(a, b) -> int:
    return sum(abs(x - y) for x, y in zip(a, b, strict=True))


@st.composite
def frontier_frames(draw: st.DrawFn) -> tuple[float, float, list[tuple[float, dict, tuple]]]:
    """A power budget, a period and a sequence of frames: (time, {setting: (power, error)} of that frame's
    frontier, target), power ascending and error descending along the frontier, the target being the
    frontier's least-error point within the budget when any is (the last point within it), else the
    cheapest."""
    budget = draw(st.floats(0.5, 3.0))
    period = draw(st.sampled_from([0.5, 1.0, 2.0]))
    frames = []
    t = 0.0
    for _ in range(draw(st.integers(2, 40))):
        t += draw(st.sampled_from([1 / 30, 0.1, 0.4, 1.3]))
        pts = draw(st.lists(setting, min_size=1, max_size=6, unique=True))
        n = len(pts)
        powers = sorted(draw(st.lists(st.floats(0.1, 4.0), min_size=n, max_size=n)))
        errors = sorted(draw(st.lists(error, min_size=n, max_size=n)), reverse=True)
        frontier = dict(zip(pts, zip(powers, errors, strict=True), strict=True))
        within = [p for p in pts if frontier[p][0] <= budget]
        frames.append((t, frontier, within[-1] if within else pts[0]))
    return budget, period, frames


@settings(max_examples=300, deadline=None)
@given(frontier_frames())
def test_every_filtered_setting_keeps_the_power_budget_when_the_target_does(case) -> None:
    budget, period, frames = case
    f = TemporalFilter(period)
    for t, frontier, target in frames:
        allowed = {p: e for p, (w, e) in frontier.items() if w <= budget} or {target: frontier[target][1]}
        shown = f.update(target, t, allowed)
        assert shown in allowed  # a point of this frame's frontier that keeps the budget ...
        if frontier[target][0] <= budget:
            assert frontier[shown][0] <= budget  # ... whenever the target does


@st.composite
def transitions(draw: st.DrawFn) -> tuple[dict, tuple, tuple, float, float]:
    """Allowed points with predicted errors, the settings on screen (allowed or not), a target among the
    allowed points, the period and the moment the target changes."""
    points = draw(st.lists(setting, min_size=1, max_size=8, unique=True))
    errors = draw(st.lists(error, min_size=len(points), max_size=len(points)))
    allowed = dict(zip(points, errors, strict=True))
    return (allowed, draw(setting), draw(st.sampled_from(points)), draw(st.sampled_from([0.5, 2.0])),
            draw(st.floats(0.01, 5.0)))


@settings(max_examples=300, deadline=None)
@given(transitions(), error)
def test_the_filter_moves_towards_the_target_and_reaches_it_after_t(case, old_error) -> None:
    allowed, old, target, period, t0 = case
    f = TemporalFilter(period)
    assert f.update(old, 0.0, {old: old_error}) == old
    # the target changes at t0; the allowed points stay the same over the transition
    shown = f.update(target, t0, allowed)
    if old in allowed:
        assert shown == old  # no pop: the settings on screen stay while they are allowed
    gap = abs(allowed[shown] - allowed[target])
    for k in range(1, 31):
        t = t0 + period * k / 30
        shown = f.update(target, t, allowed)
        now = abs(allowed[shown] - allowed[target])
        assert shown in allowed and now <= gap  # never away from the target (in predicted error)
        gap = now
    assert shown == target  # reached after exactly T
    assert f.update(target, t0 + 10 * period, allowed) == target


@settings(max_examples=300, deadline=None)
@given(transitions())
def test_no_detour_the_shown_error_stays_between_the_start_and_the_target(case) -> None:
    """While the settings on screen are allowed when the target changes, every shown setting's predicted
    error lies between theirs and the target's and follows Eq. 8's pace in error as closely as the
    allowed points permit: no detour through points less accurate than both ends."""
    allowed, _, target, period, t0 = case
    old = next(iter(allowed))
    f = TemporalFilter(period)
    f.update(old, 0.0, allowed)
    lo, hi = sorted((allowed[old], allowed[target]))
    for k in range(30):
        a = k / 30
        shown = f.update(target, t0 + period * a, allowed)
        assert lo <= allowed[shown] <= hi
        wanted = (1 - a) * allowed[old] + a * allowed[target]
        assert abs(allowed[shown] - wanted) <= abs(allowed[target] - wanted) + 1e-12  # as near as the end


def test_mid_transition_stays_near_the_ends_in_error_not_on_a_cheap_point_near_in_index_space() -> None:
    """The case the index-space rule got wrong: half-way from (0, 4, 0) to (4, 0, 0), Eq. 8's blend of
    indices is (2, 2, 0), nearest (in index space) to the cheap (1, 1, 0), whose error is five times the
    ends'; in error the ends are 0.12 and 0.10, so the filter shows an end or the point between them. A
    move of 0.02 across allowed errors spanning 0.7 lasts 0.02 / 0.7 of T."""
    allowed = {(0, 0, 0): 0.8, (1, 1, 0): 0.6, (0, 4, 0): 0.12, (4, 0, 0): 0.10, (3, 1, 2): 0.11}
    f = TemporalFilter(2.0)
    f.update((0, 4, 0), 0.0, allowed)
    period = transition_period(2.0, 0.12, 0.10, allowed.values())
    assert period == pytest.approx(2.0 * 0.02 / 0.7)
    times = [period * k / 20 for k in range(21)]
    shown = [f.update((4, 0, 0), t, allowed) for t in times]
    assert [allowed[s] for s in shown] == sorted((allowed[s] for s in shown), reverse=True)
    assert max(allowed[s] for s in shown) <= 0.12 and (3, 1, 2) in shown
    assert (1, 1, 0) not in shown and shown[0] == (0, 4, 0) and shown[-1] == (4, 0, 0)


@given(error, error, st.lists(error, max_size=6), st.floats(0.1, 5.0))
def test_a_transition_lasts_its_share_of_the_allowed_error_span_of_t(start, target, others, period) -> None:
    """The whole span of the allowed errors in T, a shorter move in proportionally less, never over T."""
    allowed = [target, *others]
    p = transition_period(period, start, target, allowed)
    move, width = abs(start - target), max(allowed) - min(allowed)
    assert 0.0 <= p <= period
    if move >= width:
        assert p == (period if move > 0 else 0.0)  # across the whole span (or further): T
    else:
        assert p == pytest.approx(period * move / width)  # a share of it: that share of T
    assert (p == 0.0) == (start == target)


def test_targets_of_about_the_shown_quality_keep_it() -> None:
    """Targets that change every second between settings of about the same error (neighbouring view
    cubes) keep the shown error near theirs; the index-space rule went through the cheap points that lie
    near the blend of the targets' indices ((4, 0, 0) to (0, 4, 0) half-way is (2, 2, 0): next to the
    cheap (2, 1, 0))."""
    allowed = {(0, 0, 0): 0.7, (2, 1, 0): 0.6, (1, 0, 2): 0.6, (4, 0, 0): 0.21, (0, 4, 0): 0.20,
               (0, 0, 4): 0.20}
    f = TemporalFilter(2.0)
    f.update((4, 0, 0), 0.0, allowed)
    targets = [(0, 4, 0)] * 10 + [(0, 0, 4)] * 10 + [(0, 4, 0)] * 10
    shown = [f.update(target, 0.1 * (k + 1), allowed) for k, target in enumerate(targets)]
    assert all(allowed[s] <= 0.21 for s in shown)


@given(setting, setting, st.floats(0.0, 1.0))
def test_without_allowed_points_it_is_eq_8(old, new, a) -> None:
    expect = tuple(math.floor((1 - a) * o + a * n + 0.5) for o, n in zip(old, new, strict=True))
    assert blend(old, new, a) == (tuple(new) if a >= 1 else expect)


def test_allowed_points_must_include_the_target_and_have_finite_errors() -> None:
    f = TemporalFilter(1.0)
    with pytest.raises(ValueError):
        f.update((1, 1, 1), 0.0, {(0, 0, 0): 0.1})
    with pytest.raises(ValueError):
        f.update((1, 1, 1), 0.0, {(1, 1, 1): math.nan})


def test_a_new_target_mid_transition_starts_from_the_shown_setting() -> None:
    pts = {(0, 0, 0): 0.4, (1, 1, 1): 0.3, (2, 2, 2): 0.2, (3, 3, 3): 0.1}
    f = TemporalFilter(1.0)
    f.update((0, 0, 0), 0.0, pts)
    assert f.update((3, 3, 3), 0.1, pts) == (0, 0, 0)
    mid = f.update((3, 3, 3), 0.6, pts)
    assert mid in ((1, 1, 1), (2, 2, 2))
    assert f.update((0, 0, 0), 0.7, pts) == mid  # back: from the shown setting, no pop
    assert f.update((0, 0, 0), 1.7, pts) == (0, 0, 0)
    assert f.update((3, 3, 3), 0.2, pts) == (3, 3, 3)  # time backwards (scrubbing): snap


def test_a_setting_that_left_the_frontier_starts_at_the_error_it_was_shown_at() -> None:
    """When the settings on screen are not among the new frame's allowed points, the transition starts at
    the error they were shown at (not at an unrelated point near them in index space)."""
    f = TemporalFilter(1.0)
    f.update((2, 2, 2), 0.0, {(2, 2, 2): 0.3})
    here = {(2, 2, 1): 0.9, (0, 0, 5): 0.31, (5, 5, 5): 0.05}
    assert f.update((5, 5, 5), 0.1, here) == (0, 0, 5)


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
    its frame's frontier, within the power (error) budget whenever the target is, and predicted for the
    frame's camera (never above the stored worst figures); the target holds T after it last changed."""
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
            # predicted for this camera (between the frontier's pricing cameras' figures), never above the
            # stored worst figures, which keep the budget
            points = {p.packed: p for p in store.budget_points(hit)}
            assert (pf.predicted_error, pf.predicted_power_w) == store.expected(hit, points[shown])
            assert pf.predicted_power_w <= float(fr.power_w[j]) + 1e-9
            assert pf.predicted_error <= float(fr.error[j]) + 1e-12
            if not hit.infeasible:
                if mode == "POWER":
                    assert float(fr.power_w[j]) <= budget
                else:
                    assert float(fr.error[j]) <= budget
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
