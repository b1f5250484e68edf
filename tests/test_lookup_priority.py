"""Frontiers that keep the accurate settings missing the frame rate (the slow tier, store format 5) and
the lookup's priority: frame rate first (the default, the answers of before) or budget first.

Property tests over random points and stores (the stores of ``test_store_lookup``), brute-force
answers for the budget-first rule, the store's round trip with slow points, a version-4 store, lookups
at a lower frame rate, and a small real optimisation whose store has a slow tier."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.store import Frontier, ParetoStore, frontier_tiers, pack_indices
from tests.test_store_lookup import PARAMS, budgets, orientations, positions, stores

FPS = 30.0


def _dominated_or_equal(a: tuple[float, float], by: tuple[float, float]) -> bool:
    """Whether point ``a`` (error, power) is weakly dominated by ``by``."""
    return by[0] <= a[0] and by[1] <= a[1]


@settings(max_examples=200, deadline=None)
@given(pts=st.lists(st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 20.0),
                              st.one_of(st.floats(0.0, 0.1), st.sampled_from([1 / FPS, 0.0, 1.0]))),
                    min_size=1, max_size=30))
def test_a_frontier_keeps_both_tiers_each_non_dominated(pts: list[tuple[float, float, float]]) -> None:
    err = [p[0] for p in pts]
    pw = [p[1] for p in pts]
    t = [p[2] for p in pts]
    fr = Frontier.from_points(range(len(pts)), err, pw, t, fps=FPS)
    meets = [v <= 1 / FPS for v in t]
    fast, slow = fr.tiers(FPS)
    assert np.all(np.diff(fr.error) < 0)  # error descends over the whole frontier
    for tier in (fast, slow) if slow is not None else (fast,):
        assert np.all(np.diff(tier.power_w) > 0) and np.all(np.diff(tier.error) < 0)  # non-dominated
    if not any(meets) or all(meets):  # one tier: the front of every setting
        assert slow is None
        for e, p in zip(err, pw, strict=True):
            assert any(_dominated_or_equal((e, p), q) for q in zip(fast.error, fast.power_w, strict=True))
        return
    assert np.all(fast.frame_time_s <= 1 / FPS)
    best = float(fast.error.min())
    # every meeting setting is covered by the meeting tier; every missing one more accurate than the
    # best meeting one by the slow tier (which is strictly more accurate than the meeting tier)
    for e, p, m in zip(err, pw, meets, strict=True):
        if m:
            assert any(_dominated_or_equal((e, p), q) for q in zip(fast.error, fast.power_w, strict=True))
        elif e < best:
            assert slow is not None
            assert any(_dominated_or_equal((e, p), q) for q in zip(slow.error, slow.power_w, strict=True))
    if slow is not None:
        assert np.all(slow.frame_time_s > 1 / FPS) and float(slow.error.max()) < best
    # the same tiers as the function the search draws its frontiers with
    f_idx, s_idx = frontier_tiers(err, pw, meets)
    assert fr.packed.tolist() == f_idx + s_idx


def _budget_first(store: ParetoStore, fid: int, budget: dict) -> tuple[int, bool, bool | None] | None:
    """The budget-first rule by brute force over a stored frontier at the store's rate: (packed, meets,
    infeasible) of the point to choose, or None when no point keeps the budget."""
    fr = store.frontiers[fid]
    meets = (np.ones(len(fr), dtype=bool) if fr.frame_time_s is None
             else fr.frame_time_s <= 1.0 / store.fps)
    if "error_budget" in budget:
        within = fr.error <= budget["error_budget"]
        key = fr.power_w  # least power, then least error
        tie = fr.error
    else:
        within = fr.power_w <= budget["power_budget"]
        key = fr.error  # least error, then least power
        tie = fr.power_w
    for tier in (within & meets, within & ~meets):
        if tier.any():
            k = min(np.flatnonzero(tier), key=lambda i: (key[i], tie[i]))
            return int(fr.packed[k]), bool(meets[k]), False
    return None


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_budget_first_keeps_the_budget_whenever_a_stored_point_does(data: st.DataObject) -> None:
    store = data.draw(stores())
    for _ in range(8):
        pose = data.draw(orientations())
        where = data.draw(positions(store))
        budget = data.draw(budgets(store))
        try:
            rate_first = store.lookup(where, **pose, **budget)
        except ValueError:  # a degenerate pose (test_store_lookup checks the message)
            continue
        assert rate_first.priority == "frame_rate"
        assert store.lookup(where, **pose, **budget, priority="frame_rate") == rate_first
        hit = store.lookup(where, **pose, **budget, priority="budget")
        assert hit.priority == "budget" and (hit.corner, hit.view) == (rate_first.corner, rate_first.view)
        want = _budget_first(store, hit.frontier, budget)
        value = budget.get("error_budget", budget.get("power_budget"))
        kept = hit.error <= value if "error_budget" in budget else hit.power_w <= value
        if want is None:  # nothing keeps the budget: today's fallback
            assert hit.infeasible and hit.packed == rate_first.packed and not kept
        else:
            assert not hit.infeasible and kept and hit.packed == want[0]
            if store.frame_times_known:
                assert hit.meets_fps is want[1]
            if not rate_first.infeasible:  # a meeting point keeps it: the same answer as frame rate first
                assert hit == rate_first.__class__(**{**rate_first.__dict__, "priority": "budget"})
        points = store.budget_points(hit)
        assert hit.indices in [p.indices for p in points]
        if hit.infeasible:
            assert len(points) == 1
            continue
        for p in points:  # every point the temporal filter may show keeps the budget ...
            assert (p.error <= value) if "error_budget" in budget else (p.power_w <= value)
            assert p.meets_fps == hit.meets_fps  # ... from the tier the choice came from
        fr = store.frontiers[hit.frontier]
        if fr.frame_time_s is not None and hit.meets_fps is False:
            missing = fr.frame_time_s > 1.0 / store.fps
            if not missing.all():  # the slow tier's points within the budget, all of them
                within = (fr.error <= value) if "error_budget" in budget else (fr.power_w <= value)
                assert sorted(p.packed for p in points) == sorted(fr.packed[within & missing].tolist())


def _two_tier_store(fps: float = FPS) -> ParetoStore:
    """One leaf, six view frontiers drawn with the two-tier rule: the real-time settings reach error 0.05
    at best; the max-quality one (error 0) takes 0.1 s and one more accurate setting 0.05 s."""
    corners = np.array([[(k & 1), (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], dtype=np.int64)
    frontiers = []
    for v in range(6):
        settings_ = [pack_indices([a, b, c]) for a, b, c in ((0, 0, 0), (1, 0, 1), (1, 1, 2), (2, 1, 3),
                                                             (2, 0, 3), (0, 1, 1))]
        err = [0.0, 0.01 + 0.001 * v, 0.05, 0.2, 0.3, 0.02]
        power = [1.0, 0.95, 0.6, 0.3, 0.2, 1.2]  # the last is dominated by the second (same tier)
        times = [0.1, 0.05, 0.03, 0.01, 0.02, 0.06]
        frontiers.append(Frontier.from_points(settings_, err, power, times, fps=fps))
    return ParetoStore(PARAMS, np.zeros(3), 10.0, 0, np.array([-1]), corners,
                       np.tile(np.arange(6), (8, 1)), frontiers, fps=fps, meta={"static_power_w": 0.1})


def test_budget_first_picks_a_slow_setting_only_when_no_real_time_one_keeps_the_budget() -> None:
    s = _two_tier_store()
    fr = s.frontiers[0]
    assert len(fr) == 5 and len(fr.meeting(FPS)) == 3  # setting (0, 1, 1) is dominated in its tier
    where, look = (5.0, 5.0, 5.0), (1.0, 0.0, 0.0)
    rate_first = s.lookup(where, direction=look, error_budget=0.02)
    assert rate_first.infeasible and rate_first.meets_fps and rate_first.error == 0.05
    hit = s.lookup(where, direction=look, error_budget=0.02, priority="budget")
    # the cheapest setting within 0.02: 0.05 s a frame (20 fps), not max quality
    assert not hit.infeasible and hit.meets_fps is False and hit.fps == pytest.approx(20.0, rel=1e-4)
    assert hit.indices == (1, 0, 1) and hit.error <= 0.02 and hit.priority == "budget"
    assert [p.indices for p in s.budget_points(hit)] == [(1, 0, 1), (0, 0, 0)]
    assert [p.indices for p in s.budget_points(rate_first)] == [rate_first.indices]
    exact = s.lookup(where, direction=look, error_budget=0.0, priority="budget")
    assert exact.indices == (0, 0, 0) and exact.error == 0.0 and not exact.infeasible
    # a budget a real-time setting keeps: the same answer under both priorities
    easy = s.lookup(where, direction=look, error_budget=0.06, priority="budget")
    assert easy.meets_fps and easy.indices == s.lookup(where, direction=look, error_budget=0.06).indices
    # power budgets: least error among the real-time settings within it, as before
    cheap = s.lookup(where, direction=look, power_budget=0.9, priority="budget")
    assert cheap.meets_fps and cheap.error == 0.05
    none = s.lookup(where, direction=look, power_budget=0.1, priority="budget")
    assert none.infeasible and none.power_w == 0.2  # nothing keeps it: the cheapest, as before
    assert s.lookup(where, direction=look, error_budget=-1.0, priority="budget").infeasible
    with pytest.raises(ValueError, match="priority"):
        s.lookup(where, direction=look, error_budget=0.02, priority="speed")
    with pytest.raises(ValueError, match="priority"):
        s.lookup(where, direction=look, error_budget=0.02, priority=None)  # type: ignore[arg-type]


def test_a_lower_frame_rate_finds_the_slow_points_that_meet_it() -> None:
    s = _two_tier_store()
    where, look = (5.0, 5.0, 5.0), (1.0, 0.0, 0.0)
    hit = s.lookup(where, direction=look, error_budget=0.02, fps=20.0)  # 0.05 s a frame meets 20 fps
    assert not hit.infeasible and hit.meets_fps and hit.indices == (1, 0, 1) and hit.fps == 20.0
    assert [p.indices for p in s.budget_points(hit)] == [(1, 0, 1)]
    slow = s.lookup(where, direction=look, error_budget=0.0, fps=20.0)  # max quality still misses 20 fps
    assert slow.infeasible and slow.meets_fps
    first = s.lookup(where, direction=look, error_budget=0.0, fps=20.0, priority="budget")
    assert not first.infeasible and first.meets_fps is False and first.indices == (0, 0, 0)
    assert first.fps == pytest.approx(10.0, rel=1e-4)


def test_round_trip_keeps_the_slow_tier_and_a_version_4_store_still_reads() -> None:
    s = _two_tier_store()
    text = s.to_json()
    doc = json.loads(text)
    assert doc["version"] == 6
    back = ParetoStore.from_json(text)
    assert back.to_json() == text
    for a, b in zip(s.frontiers, back.frontiers, strict=True):
        for ta, tb in zip(a.tiers(FPS), b.tiers(FPS), strict=True):
            assert ta is not None and tb is not None and ta.packed.tolist() == tb.packed.tolist()
            assert np.allclose(ta.error, tb.error, atol=1e-4)
            assert np.allclose(ta.power_w, tb.power_w, rtol=1e-4)
    for budget in (0.0, 0.015, 0.02, 0.06, 0.5):  # (off the points: errors are kept in 16-bit steps)
        for priority in ("frame_rate", "budget"):
            kw = {"direction": (1.0, 0.0, 0.0), "error_budget": budget, "priority": priority}
            got, want = back.lookup((5.0, 5.0, 5.0), **kw), s.lookup((5.0, 5.0, 5.0), **kw)
            assert (got.indices, got.meets_fps, got.infeasible) == (want.indices, want.meets_fps,
                                                                    want.infeasible)
    # a version-4 store (meeting points only, as they were written) reads, and both priorities agree
    v4 = ParetoStore(s.parameters, s.root_min, s.root_size, 0, s.children, s.corner_coords, s.corner_views,
                     [f.meeting(FPS) for f in s.frontiers], fps=FPS)
    old = v4.to_dict()
    old["version"] = 4
    read = ParetoStore.from_dict(old)
    assert all(f.tiers(FPS)[1] is None for f in read.frontiers)
    for priority in ("frame_rate", "budget"):
        hit = read.lookup((5.0, 5.0, 5.0), direction=(1.0, 0.0, 0.0), error_budget=0.02, priority=priority)
        assert hit.infeasible and hit.meets_fps and hit.error == pytest.approx(0.05, abs=1e-4)
    bad = dict(doc, version=7)
    with pytest.raises(ValueError, match="version"):
        ParetoStore.from_dict(bad)


@pytest.mark.slow
def test_a_real_store_keeps_the_settings_too_slow_for_its_frame_rate() -> None:
    """The tests' teapot optimised for 120 fps, where its max-quality setting does not keep up: every
    frontier ends with the slow tier (max quality, error 0, included), priced as measured, a
    budget-first lookup keeps an error budget no real-time setting keeps, and the searches' probes put
    a setting between max quality and the real-time ones in a slow tier (max quality alone without them)."""
    from tracer_scenes import teapot_scene

    from service.camera_path import CameraPath
    from service.eval_cache import EvalCache
    from service.evaluation import CameraSpec, Evaluator
    from service.executors import InProcessExecutor
    from service.optimize import OptimizeConfig, optimize_path
    from service.params import default_space
    from service.store import unpack_indices, view_up

    scene = teapot_scene()
    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])
    ang = np.linspace(-0.6, 0.9, 4)
    pos = [(6.0 * np.sin(a), -6.0 * np.cos(a), 2.5) for a in ang]
    path = CameraPath.from_positions(pos, [(-x, -y, 0.6 - z) for x, y, z in pos], vfov=0.7,
                                     resolution=(320, 240))
    cfg = OptimizeConfig(threshold_power_w=0.01, threshold_error=0.005, max_depth=2, population=6,
                         generations=3, exhaustive_limit=0, eval_width=16, eval_height=12, seed=3,
                         view_sampling="path", path_resolution=0.5, guard_frames=0,
                         display_estimator="preview", fps=120.0)
    cache = EvalCache()
    store = optimize_path(scene, path, space, cfg, cache=cache, executor=InProcessExecutor())
    assert store.fps == 120.0 and store.to_dict()["version"] == 6
    period = 1.0 / store.fps
    slow_tiers = 0
    for fr in store.frontiers:
        fast, slow = fr.tiers(store.fps)
        assert float(fr.error.min()) == 0.0  # max quality is on every frontier
        if slow is None:
            continue
        slow_tiers += 1
        assert np.all(slow.frame_time_s > period) and np.all(fast.frame_time_s <= period)
        assert float(slow.error.max()) < float(fast.error.min()) and float(slow.error.min()) == 0.0
    assert slow_tiers > 0
    # the slow points are what the search measured at the frontier's camera
    ev = Evaluator(scene, space, cache=cache, profile="mobile", fps=120.0, target_pixels=320 * 240)
    for fid, fr in enumerate(store.frontiers):
        _, slow = fr.tiers(store.fps)
        if slow is None:
            continue
        eye, fwd = store.frontier_eyes[fid], store.frontier_dirs[fid]
        cam = CameraSpec(tuple(eye), tuple(fwd), tuple(view_up(fwd)), store.vfov, 16, 12)
        got = ev.evaluate([(cam, unpack_indices(int(p), store.n_params)) for p in slow.packed])
        assert np.allclose([g.error for g in got], slow.error) and all(g.frame_time_s > period for g in got)
    assert ev.evaluations == 0
    # a budget no real-time setting keeps along the path: kept with budget first, at the rate reached
    for f in path.frames:
        fr = store.frontier(*store.locate(f.position, direction=f.direction))
        budget = 0.5 * float(fr.meeting(store.fps).error.min())
        if budget <= 0.0:
            continue
        hit = store.lookup(f.position, direction=f.direction, error_budget=budget, priority="budget")
        assert not hit.infeasible and hit.error <= budget and hit.meets_fps is False
        assert hit.fps is not None and hit.fps < 120.0 and math.isfinite(hit.power_w)
        assert store.lookup(f.position, direction=f.direction, error_budget=budget).infeasible
    # the searches' probes of the slow region (Search.probes) give a slow tier a point between max
    # quality and the real-time settings, which a budget between picks instead of max quality
    assert store.meta["probe_evaluations"] > 0
    picked = 0
    for f in path.frames:
        fr = store.frontier(*store.locate(f.position, direction=f.direction))
        fast, slow = fr.tiers(store.fps)
        if slow is None or len(slow) < 2:
            continue
        budget = float(slow.error[-2])  # the slow tier's least error but max quality's (0)
        assert 0.0 < budget < float(fast.error.min())
        hit = store.lookup(f.position, direction=f.direction, error_budget=budget, priority="budget")
        assert hit.meets_fps is False and hit.error == pytest.approx(budget)
        assert hit.indices != space.max_quality_indices()
        picked += 1
    assert picked > 0


def test_playback_under_budget_first_shows_only_points_within_each_frames_budget() -> None:
    """The playback driver (what the campaign's ``filtered_frames`` steps) passes each hit to
    ``budget_points``: as the error budget tightens past what real-time settings reach, the filter moves
    to the slow tier and every shown setting is a stored point within that frame's budget."""
    from addon.core.playback_logic import PlaybackDriver
    from service.store.camera import look_matrix

    s = _two_tier_store()
    driver = PlaybackDriver(s, 1.0)
    m = look_matrix((5.0, 5.0, 5.0), (1.0, 0.0, 0.0)).tolist()
    shown = []
    for k in range(90):  # 3 s at 30 fps: budget 0.06, then 0.015 from 1 s on
        budget = 0.06 if k < 30 else 0.015
        pf = driver.step(m, 0.69, 16 / 9, k / 30, "ERROR", budget, priority="budget")
        assert pf.predicted_error <= budget and not pf.infeasible and pf.priority == "budget"
        shown.append((pf.active_indices, pf.meets_fps))
    assert shown[0] == ((1, 1, 2), True) and shown[-1] == ((1, 0, 1), False)
