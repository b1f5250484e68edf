"""Per-camera frame times (``service.store.priced``, ``service.store.lookup``): a frontier priced at its
sample camera and guard cameras keeps each point's worst frame time (which draws its stored tiers) and
each camera's own; the lookup predicts a point's frame time at the frame's camera by the same
interpolation as its error and power and draws the frame's tiers from that prediction. A setting that
keeps up at the sample camera but misses the rate at a far guard is a real-time setting next to the
sample (the frame-rate-first lookup may pick it there) and a slow one next to the guard; budgets are
still checked against the stored worst figures. Stores without per-camera frame times choose as
before."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from addon.core.playback_logic import PlaybackDriver
from service.store import Frontier, ParetoStore, StoredParameter, pack_indices, view_up
from service.store.codec import quantise_directions, quantise_eyes
from service.store.frame_rate import meets_frame_rate
from service.store.priced import PricedFigures

PARAMS = (StoredParameter("a", (0, 1, 2, 3), 3), StoredParameter("b", (0.5, 1.0), 1))
ROOT_MIN, ROOT_SIZE = np.zeros(3), 8.0
FPS = 30.0
SAMPLE = ((2.0, 2.0, 2.0), (1.0, 0.0, 0.0))
GUARD = ((6.0, 2.0, 2.0), (1.0, 0.3, 0.0))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _store(cams, err: np.ndarray, pw: np.ndarray, ft: np.ndarray, *, per_camera_times: bool = True,
           scale: float = 2.0, fps: float = FPS) -> ParetoStore:
    """A store of one leaf whose every (corner, view) reads one frontier priced at ``cams`` (eye,
    forward; the sample first) with figures ``err``, ``pw``, ``ft`` (K, n): the frontier keeps the worst
    over the cameras, as the path sampler does, and (``per_camera_times``) each camera's frame times."""
    n = err.shape[1]
    packed = [pack_indices([i % 4, i // 4]) for i in range(n)]
    eyes = quantise_eyes(np.asarray([c[0] for c in cams], dtype=np.float64), ROOT_MIN, ROOT_SIZE)
    fwd = quantise_directions(np.asarray([_unit(c[1]) for c in cams]), fine=True)
    fr = Frontier.from_points(packed, err.max(axis=0).tolist(), pw.max(axis=0).tolist(),
                              ft.max(axis=0).tolist(), fps)
    order = [packed.index(int(p)) for p in fr.packed]
    figures = PricedFigures(eyes, fwd, scale, fr.packed, err[:, order], pw[:, order],
                            ft[:, order] if per_camera_times else None)
    coords = np.asarray([(k & 1, (k >> 1) & 1, (k >> 2) & 1) for k in range(8)], dtype=np.int64)
    return ParetoStore(parameters=PARAMS, root_min=ROOT_MIN, root_size=ROOT_SIZE, lattice_depth=1,
                       children=np.asarray([-1]), corner_coords=coords * 2,
                       corner_views=np.zeros((8, 6), dtype=np.int64), frontiers=[fr], fps=fps,
                       meta={"static_power_w": 1.0}, frontier_dirs=fwd[:1], frontier_eyes=eyes[:1],
                       priced=[figures])


def _lab_like(per_camera_times: bool = True) -> ParetoStore:
    """Three settings priced at the sample and a guard: A cheap and inaccurate (error 0.08), real-time at
    both; B within 0.02 (error 0.01), 25 ms a frame at the sample (keeps up with 30 fps) but 45 ms at
    the guard (misses it: by its worst frame time a slow point); C, maximum quality, slow at both."""
    err = np.array([[0.08, 0.008, 0.0], [0.08, 0.01, 0.0]])
    pw = np.array([[3.0, 6.0, 8.0], [3.1, 5.5, 8.0]])
    ft = np.array([[0.010, 0.025, 0.060], [0.011, 0.045, 0.060]])
    return _store([SAMPLE, GUARD], err, pw, ft, per_camera_times=per_camera_times, scale=2.0)


B = pack_indices([1, 0])


def test_a_point_slow_only_at_the_guard_is_real_time_at_the_sample_camera() -> None:
    """Frame rate first under an error budget of 0.02: at the sample camera B is predicted to keep up
    (25 ms) and is picked (its stored, worst error 0.01 keeps the budget); at the guard camera B is
    predicted to miss the rate and the lookup keeps to the real-time A (nothing real-time keeps the
    budget there: infeasible), as it did everywhere before per-camera frame times."""
    store = _lab_like()
    at_sample = store.lookup(SAMPLE[0], direction=SAMPLE[1], error_budget=0.02)
    assert at_sample.packed == B and not at_sample.infeasible
    assert at_sample.error == pytest.approx(0.01, abs=1e-4)  # the bound the budget was checked against
    assert at_sample.meets_fps is True and at_sample.fps == FPS
    assert at_sample.frame_time_s == pytest.approx(0.025, rel=1e-3)  # the prediction at this camera
    at_guard = store.lookup(GUARD[0], direction=GUARD[1], error_budget=0.02)
    assert at_guard.packed == pack_indices([0, 0]) and at_guard.infeasible and at_guard.meets_fps is True
    # budget first at the guard: B from the frame's slow tier, reported slow at its predicted rate
    budget_first = store.lookup(GUARD[0], direction=GUARD[1], error_budget=0.02, priority="budget")
    assert budget_first.packed == B and budget_first.meets_fps is False
    assert budget_first.fps == pytest.approx(1 / 0.045, rel=1e-3)
    # the same store without per-camera frame times: B is slow for every frame (its worst camera's)
    old = _lab_like(per_camera_times=False)
    before = old.lookup(SAMPLE[0], direction=SAMPLE[1], error_budget=0.02)
    assert before.packed == pack_indices([0, 0]) and before.infeasible
    assert before.meeting == -1 and before.frame_time_s == pytest.approx(0.011, rel=1e-3)


def test_the_frames_tier_moves_with_the_camera_between_sample_and_guard() -> None:
    """Along the line from the sample to the guard, B is picked while its interpolated frame time keeps
    up with 30 fps and not after; the reported frame time is that interpolation."""
    store = _lab_like()
    figures = store.priced[0]
    j = figures.point(B)
    picked = []
    for s in np.linspace(0.0, 1.0, 21):
        eye = (1 - s) * np.asarray(SAMPLE[0]) + s * np.asarray(GUARD[0])
        fwd = _unit((1 - s) * _unit(SAMPLE[1]) + s * _unit(GUARD[1]))
        hit = store.lookup(eye, direction=fwd, error_budget=0.02)
        t = figures.frame_time(hit.weights, j)
        assert 0.025 - 1e-6 <= t <= 0.045 + 1e-6
        assert (hit.packed == B) == meets_frame_rate(t, FPS)
        picked.append(hit.packed == B)
    assert picked[0] and not picked[-1]
    assert picked == sorted(picked, reverse=True)  # once slow, slow for the rest of the way


def test_budget_points_are_the_tier_of_the_hits_own_frame() -> None:
    """The temporal filter's allowed points come from the tier of the frame the hit was looked up at,
    also after a lookup at another frame with other tiers; each with its prediction at that frame."""
    store = _lab_like()
    at_sample = store.lookup(SAMPLE[0], direction=SAMPLE[1], error_budget=0.05)
    at_guard = store.lookup(GUARD[0], direction=GUARD[1], error_budget=0.05)
    assert at_sample.meeting != at_guard.meeting
    sample_points = store.budget_points(at_sample)  # after the guard's lookup
    assert [p.packed for p in sample_points] == [B]
    assert sample_points[0].meets_fps is True and sample_points[0].frame_time_s == pytest.approx(0.025, 1e-3)
    assert [p.packed for p in store.budget_points(at_guard)] == [pack_indices([0, 0])]  # infeasible: itself
    wide = store.lookup(SAMPLE[0], direction=SAMPLE[1], error_budget=0.1)
    assert wide.packed == pack_indices([0, 0])
    assert sorted(p.packed for p in store.budget_points(wide)) == sorted([pack_indices([0, 0]), B])
    assert all(p.meets_fps for p in store.budget_points(wide))
    # a result names its frame's tiers; one naming points the frontier does not have is refused
    with pytest.raises(ValueError):
        store.budget_points(dataclasses.replace(wide, meeting=1 << 10))


def test_another_frame_rate_draws_the_frames_tiers_at_that_rate() -> None:
    """At 24 fps (41.7 ms) B keeps up at the sample, not at the guard (45 ms); at 20 fps (50 ms) it keeps
    up at both (the store's tiers at that rate)."""
    store = _lab_like()
    assert store.lookup(SAMPLE[0], direction=SAMPLE[1], error_budget=0.02, fps=24.0).packed == B
    guard = store.lookup(GUARD[0], direction=GUARD[1], error_budget=0.02, fps=24.0)
    assert guard.packed != B and guard.infeasible
    for cam in (SAMPLE, GUARD):
        hit = store.lookup(cam[0], direction=cam[1], error_budget=0.02, fps=20.0)
        assert hit.packed == B and hit.meets_fps is True and hit.fps == 20.0
        assert {p.packed for p in store.budget_points(hit)} == {B}


def test_another_frame_rate_reprices_each_cameras_power_with_its_own_frame_time() -> None:
    """The prediction's power at another rate: each camera's power repriced with that camera's frame
    time (B keeps up at the sample at 24 fps, so it draws 24 frames' energy there), then interpolated."""
    from service.store.frame_rate import power_at_rate

    store = _lab_like()
    hit = store.lookup(SAMPLE[0], direction=SAMPLE[1], error_budget=0.02, fps=24.0)
    assert hit.packed == B and hit.weights[0] > 0.999
    assert hit.expected_power_w == pytest.approx(power_at_rate(6.0, 0.025, FPS, 24.0, 1.0), rel=1e-3)


def test_playback_shows_the_frames_real_time_point_and_reports_its_prediction() -> None:
    store = _lab_like()
    driver = PlaybackDriver(store, period_s=0.0)

    def matrix(cam):
        m = np.eye(4)
        f = _unit(cam[1])
        up = view_up(f)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = np.cross(f, up), up, -f, cam[0]
        return m

    near = driver.step(matrix(SAMPLE), store.vfov, store.aspect, 0.0, "ERROR", 0.02)
    assert near.active_indices == (1, 0) and near.meets_fps is True
    assert near.predicted_fps == pytest.approx(FPS)
    far = driver.step(matrix(GUARD), store.vfov, store.aspect, 1.0, "ERROR", 0.02)
    assert far.active_indices == (0, 0) and far.meets_fps is True


def test_the_command_line_query_reports_the_frames_tier_from_the_stored_document(tmp_path, capsys) -> None:
    """``render-budget query`` on the store's JSON document (per-camera frame times on the document's
    steps): at the sample camera B, real-time at 25 ms; at the guard the real-time A (infeasible)."""
    import json

    from service import cli

    f = tmp_path / "store.json"
    f.write_text(_lab_like().to_json())
    figures = ParetoStore.from_json(f.read_text()).priced[0]
    answers = []
    for eye, fwd in zip(figures.eyes, figures.forwards, strict=True):  # the stored cameras themselves
        argv = ["query", str(f), "--position", *map(repr, eye.tolist()), "--direction",
                *map(repr, fwd.tolist()), "--error-budget", "0.02", "--json"]
        assert cli.main(argv) == 0
        answers.append(json.loads(capsys.readouterr().out))
    at_sample, at_guard = answers
    assert at_sample["settings"] == {"a": 1, "b": 0.5} and not at_sample["infeasible"]
    assert at_sample["meets_fps"] is True and at_sample["frame_time_s"] == pytest.approx(0.025, rel=1e-3)
    assert at_guard["settings"] == {"a": 0, "b": 0.5} and at_guard["infeasible"]
    assert at_guard["frame_time_s"] == pytest.approx(0.011, rel=1e-3)


# ------------------------------------------------------------------------------------- properties


coord = st.floats(0.5, 7.5)
direction = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(
    lambda v: 0.2 < math.hypot(*v) and abs(v[2]) < 0.8 * math.hypot(*v))


@st.composite
def timed_stores(draw: st.DrawFn) -> ParetoStore:
    """A frontier of 1-7 settings priced at 1-3 cameras, each setting's frame time at each camera
    anywhere around the frame period (so its cameras disagree on whether it keeps up)."""
    k = draw(st.integers(1, 3))
    n = draw(st.integers(1, 7))
    cams = [(tuple(draw(st.tuples(coord, coord, coord))), draw(direction)) for _ in range(k)]
    eyes = np.asarray([c[0] for c in cams])
    assume(all(np.linalg.norm(eyes[i] - eyes[j]) > 0.1 for i in range(k) for j in range(i)))
    vals = st.lists(st.floats(0.0, 1.0), min_size=k * n, max_size=k * n)
    err = np.asarray(draw(vals)).reshape(k, n) * 0.2
    pw = 1.0 + 9.0 * np.asarray(draw(vals)).reshape(k, n)
    ft = 0.02 + 0.03 * np.asarray(draw(vals)).reshape(k, n)  # 20-50 ms around the 33.3 ms period
    return _store(cams, err, pw, ft, scale=draw(st.floats(0.5, 5.0)))


@settings(max_examples=150, deadline=None)
@given(timed_stores(), st.tuples(coord, coord, coord), direction, st.floats(0.0, 0.25), st.booleans())
def test_frame_rate_first_picks_the_least_power_predicted_real_time_point_within_the_budget(
        store, eye, fwd, budget, by_power) -> None:
    """Against a brute force over the stored points: under frame rate first, the chosen point is
    predicted to keep up at this frame whenever any point is; among the points predicted to keep up it
    is the least stored power within an error budget (the least stored error within a power budget);
    ``budget_points`` are the predicted-real-time points keeping the budget, each with its prediction."""
    fr, figures = store.frontiers[0], store.priced[0]
    mode = "power_budget" if by_power else "error_budget"
    value = 1.0 + 40.0 * budget if by_power else budget
    hit = store.lookup(eye, direction=fwd, **{mode: value})
    t = [figures.frame_time(hit.weights, j) for j in range(len(fr))]
    meets = [meets_frame_rate(v, FPS) for v in t]
    j = figures.point(hit.packed)
    assert hit.frame_time_s == t[j] and hit.meets_fps == meets[j]
    assert hit.meeting == sum(1 << i for i, m in enumerate(meets) if m)
    pool = [i for i in range(len(fr)) if meets[i]] or list(range(len(fr)))
    assert j in pool
    if by_power:
        ok = [i for i in pool if fr.power_w[i] <= value]
        if ok:
            assert not hit.infeasible and fr.error[j] == min(fr.error[i] for i in ok)
    else:
        ok = [i for i in pool if fr.error[i] <= value]
        if ok:
            assert not hit.infeasible and fr.power_w[j] == min(fr.power_w[i] for i in ok)
    assert hit.infeasible == (not ok)
    points = store.budget_points(hit)
    assert hit.packed in [p.packed for p in points]
    for p in points:
        i = figures.point(p.packed)
        assert i in pool and p.frame_time_s == t[i] and p.meets_fps == meets[i]
        assert hit.infeasible or (p.power_w if by_power else p.error) <= value


@settings(max_examples=100, deadline=None)
@given(timed_stores(), st.tuples(coord, coord, coord), direction, st.floats(0.0, 0.25),
       st.sampled_from(["frame_rate", "budget"]), st.sampled_from([30.0, 24.0]))
def test_per_camera_frame_times_that_agree_with_the_stored_ones_change_no_choice(
        store, eye, fwd, budget, priority, fps) -> None:
    """Where every camera's frame time is the stored (worst) one, the per-frame tiers are the store's:
    the same choice, budget points and predictions as the store without per-camera frame times."""
    fr, pf = store.frontiers[0], store.priced[0]
    same = dataclasses.replace(store, priced=[dataclasses.replace(
        pf, frame_time_s=np.repeat(fr.frame_time_s[None, :], pf.cameras, axis=0))])
    plain = dataclasses.replace(store, priced=[dataclasses.replace(pf, frame_time_s=None)])
    a = same.lookup(eye, direction=fwd, error_budget=budget, priority=priority, fps=fps)
    b = plain.lookup(eye, direction=fwd, error_budget=budget, priority=priority, fps=fps)
    assert dataclasses.replace(a, meeting=-1, expected_power_w=0.0) == dataclasses.replace(
        b, expected_power_w=0.0)
    assert a.expected_power_w == pytest.approx(b.expected_power_w, rel=1e-12)
    assert same.budget_points(a) == plain.budget_points(b)
