"""Per-camera figures (``service.store.priced``): a frontier priced at its sample camera and its guard
cameras keeps each point's worst figures (what the budgets are checked against) and, with them, each
camera's own; the lookup predicts a frame's error and power from those, interpolated at the frame's
camera, so a frame at a guard camera is predicted that camera's figures rather than the worst ones. The
budget choice stays the worst figures' (the same settings as a store without per-camera figures), every
prediction lies between the cameras' figures (never above the bound), and the figures survive the JSON
document. Playback (``PlaybackDriver``) and the REST query report the prediction for the camera."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from addon.core.playback_logic import PlaybackDriver
from service.store import Frontier, ParetoStore, StoredParameter, pack_indices, view_up
from service.store.codec import QMAX, quantise_directions, quantise_eyes
from service.store.priced import PricedFigures, camera_dissimilarity, shepard_weights

PARAMS = (StoredParameter("a", (0, 1, 2, 3), 3), StoredParameter("b", (0.5, 1.0), 1))
ROOT_MIN, ROOT_SIZE = np.zeros(3), 8.0

finite01 = st.floats(0.0, 1.0, allow_nan=False)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _store(cams: list[tuple[tuple[float, float, float], tuple[float, float, float]]], err: np.ndarray,
           pw: np.ndarray, scale: float = 2.0, priced: bool = True, times: np.ndarray | None = None,
           fps: float = 30.0) -> ParetoStore:
    """A store of one leaf (the root) whose every (corner, view) reads one frontier of ``err.shape[1]``
    settings, priced at ``cams`` (eye, forward; the sample first) with figures ``err``, ``pw`` (K, n):
    the frontier's own figures are the worst over the cameras."""
    n = err.shape[1]
    packed = [pack_indices([i % 4, i // 4]) for i in range(n)]
    eyes = quantise_eyes(np.asarray([c[0] for c in cams], dtype=np.float64), ROOT_MIN, ROOT_SIZE)
    fwd = quantise_directions(np.asarray([_unit(c[1]) for c in cams]), fine=True)
    fr = Frontier.from_points(packed, err.max(axis=0).tolist(), pw.max(axis=0).tolist(),
                              None if times is None else times.tolist(), fps if times is not None else None)
    order = [packed.index(int(p)) for p in fr.packed]
    figures = PricedFigures(eyes, fwd, scale, fr.packed, err[:, order], pw[:, order]) if priced else None
    coords = np.asarray([(k & 1, (k >> 1) & 1, (k >> 2) & 1) for k in range(8)], dtype=np.int64)
    return ParetoStore(parameters=PARAMS, root_min=ROOT_MIN, root_size=ROOT_SIZE, lattice_depth=1,
                       children=np.asarray([-1]), corner_coords=coords * 2,
                       corner_views=np.zeros((8, 6), dtype=np.int64), frontiers=[fr], fps=fps,
                       meta={"static_power_w": 1.0}, frontier_dirs=fwd[:1], frontier_eyes=eyes[:1],
                       priced=None if figures is None else [figures])


def _figures(draw: st.DrawFn, k: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(K, n) errors and powers of a frontier: error falls and power rises with the setting at every
    camera (a frontier at each), levels differing between cameras."""
    base_e = np.sort(np.asarray(draw(st.lists(st.floats(0.0, 0.5), min_size=n, max_size=n))))[::-1]
    base_p = np.sort(np.asarray(draw(st.lists(st.floats(1.0, 10.0), min_size=n, max_size=n))))
    de = np.asarray(draw(st.lists(st.floats(0.0, 0.3), min_size=k, max_size=k)))
    dp = np.asarray(draw(st.lists(st.floats(0.0, 3.0), min_size=k, max_size=k)))
    steps = np.arange(n) * 1e-3
    return base_e[None, :] + de[:, None], base_p[None, :] + dp[:, None] + steps[None, :]


coord = st.floats(0.5, 7.5)
direction = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(
    lambda v: 0.2 < math.hypot(*v) and abs(v[2]) < 0.8 * math.hypot(*v))


@st.composite
def priced_stores(draw: st.DrawFn) -> tuple[ParetoStore, list]:
    k = draw(st.integers(1, 3))
    n = draw(st.integers(1, 6))
    cams = [(tuple(draw(st.tuples(coord, coord, coord))), draw(direction)) for _ in range(k)]
    eyes = np.asarray([c[0] for c in cams])
    # distinct cameras (a frame at one of them is at no other)
    assume(all(np.linalg.norm(eyes[i] - eyes[j]) > 0.1 for i in range(k) for j in range(i)))
    err, pw = _figures(draw, k, n)
    return _store(cams, err, pw, scale=draw(st.floats(0.5, 5.0))), cams


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 1e6), min_size=1, max_size=5))
def test_shepard_weights_are_a_partition_of_one_and_pick_a_camera_the_frame_is_at(costs) -> None:
    w = shepard_weights(costs)
    assert len(w) == len(costs) and all(v >= 0 for v in w) and sum(w) == pytest.approx(1.0)
    at = [c <= 1e-12 for c in costs]
    if any(at):
        assert w[at.index(True)] == 1.0
    else:  # nearer cameras weigh more
        order = np.argsort(costs, kind="stable")
        assert all(w[order[i]] >= w[order[i + 1]] - 1e-15 for i in range(len(costs) - 1))


def test_shepard_weights_reject_bad_costs() -> None:
    for bad in ([], [-1.0], [math.nan], [math.inf, 1.0]):
        with pytest.raises(ValueError):
            shepard_weights(bad)


def test_the_dissimilarity_is_the_path_samplers() -> None:
    """The one camera dissimilarity: squared eye distance over the viewing distance squared plus
    squared view-direction difference (the path sampler's medoid and guard rule, the lookup's weights)."""
    a, b = np.array([1.0, 2.0, 3.0]), np.array([2.0, 0.0, 3.0])
    fa, fb = _unit([1, 0, 0]), _unit([0, 1, 0])
    assert camera_dissimilarity(a, fa, b, fb, 2.0) == pytest.approx(5 / 4 + 2)


@settings(max_examples=120, deadline=None)
@given(priced_stores(), st.tuples(coord, coord, coord), direction, st.floats(0.0, 30.0))
def test_predictions_lie_between_the_cameras_figures_and_the_choice_is_the_bounds(case, eye, fwd,
                                                                                  budget) -> None:
    store, _ = case
    plain = dataclasses.replace(store, priced=None)  # the same store without its per-camera figures
    pf = store.priced[0]
    hit = store.lookup(eye, direction=fwd, power_budget=budget)
    ref = plain.lookup(eye, direction=fwd, power_budget=budget)
    assert (hit.indices, hit.power_w, hit.error, hit.infeasible) == (ref.indices, ref.power_w, ref.error,
                                                                     ref.infeasible)
    assert (ref.expected_error, ref.expected_power_w, ref.weights) == (ref.error, ref.power_w, ())
    j = list(pf.packed).index(hit.packed)
    assert len(hit.weights) == pf.cameras and sum(hit.weights) == pytest.approx(1.0)
    assert pf.error[:, j].min() - 1e-12 <= hit.expected_error <= pf.error[:, j].max() + 1e-12
    assert pf.power_w[:, j].min() - 1e-9 <= hit.expected_power_w <= pf.power_w[:, j].max() + 1e-9
    assert hit.expected_error <= hit.error + 1e-12 and hit.expected_power_w <= hit.power_w + 1e-9
    for pt in store.budget_points(hit):  # every point the temporal filter may show, likewise
        e, p = store.expected(hit, pt)
        k = list(pf.packed).index(pt.packed)
        assert pf.error[:, k].min() - 1e-12 <= e <= pt.error + 1e-12
        assert pf.power_w[:, k].min() - 1e-9 <= p <= pt.power_w + 1e-9


@settings(max_examples=60, deadline=None)
@given(priced_stores(), st.data())
def test_a_frame_at_a_pricing_camera_is_predicted_that_cameras_figures(case, data) -> None:
    """Not the worst over the cameras (what the store predicted before: on the hall most of the
    power-budget mode's prediction error)."""
    store, _ = case
    pf = store.priced[0]
    k = data.draw(st.integers(0, pf.cameras - 1))
    budget = data.draw(st.floats(0.0, 1.0))
    hit = store.lookup(pf.eyes[k], direction=pf.forwards[k], error_budget=budget)
    j = list(pf.packed).index(hit.packed)
    assert hit.weights[k] == 1.0
    assert hit.expected_error == pytest.approx(pf.error[k, j], abs=1e-12)
    assert hit.expected_power_w == pytest.approx(pf.power_w[k, j], abs=1e-9)


def test_a_frame_next_to_the_sample_is_not_predicted_the_guards_worse_figures() -> None:
    """The sample sees error 0.03 for the setting, a guard camera far along the path 0.06 (the stored,
    worst, figure): a frame next to the sample is predicted about 0.03, one next to the guard about 0.06,
    both under the same budget choice."""
    cams = [((2.0, 2.0, 2.0), (1.0, 0.0, 0.0)), ((6.0, 2.0, 2.0), (1.0, 0.2, 0.0))]
    err = np.array([[0.03, 0.001], [0.06, 0.002]])
    pw = np.array([[5.0, 9.0], [5.5, 9.5]])
    store = _store(cams, err, pw, scale=3.0)
    near_sample = store.lookup((2.1, 2.0, 2.0), direction=(1.0, 0.0, 0.0), power_budget=6.0)
    near_guard = store.lookup((5.9, 2.0, 2.0), direction=(1.0, 0.2, 0.0), power_budget=6.0)
    assert near_sample.error == near_guard.error == pytest.approx(0.06, abs=1e-4)  # the bound
    assert near_sample.expected_error == pytest.approx(0.03, abs=1e-3)
    assert near_guard.expected_error == pytest.approx(0.06, abs=1e-3)
    assert near_sample.expected_power_w == pytest.approx(5.0, abs=0.02)


@settings(max_examples=60, deadline=None)
@given(priced_stores())
def test_per_camera_figures_survive_the_json_document(case) -> None:
    store, _ = case
    back = ParetoStore.from_json(store.to_json())
    a, b = store.priced[0], back.priced[0]
    step = float(store.to_dict()["power_scale"]) / QMAX
    assert b.cameras == a.cameras and np.array_equal(b.packed, a.packed)
    assert np.allclose(b.error, a.error, atol=0.5 / QMAX + 1e-12)
    assert np.allclose(b.power_w, a.power_w, atol=0.5 * step + 1e-9)
    assert np.allclose(b.eyes, a.eyes, atol=1e-9) and np.allclose(b.forwards, a.forwards, atol=1e-6)
    assert b.scale == pytest.approx(a.scale, rel=1e-6)
    assert ParetoStore.from_json(back.to_json()).to_json() == back.to_json()  # stable once stored


def test_a_store_without_per_camera_figures_writes_none_of_their_fields() -> None:
    cams = [((2.0, 2.0, 2.0), (1.0, 0.0, 0.0))]
    doc = _store(cams, np.array([[0.1, 0.0]]), np.array([[2.0, 3.0]]), priced=False).to_dict()
    assert not [k for k in doc if k.startswith("priced")]


def test_per_camera_figures_must_match_their_frontier() -> None:
    cams = [((2.0, 2.0, 2.0), (1.0, 0.0, 0.0)), ((3.0, 2.0, 2.0), (1.0, 0.0, 0.0))]
    store = _store(cams, np.array([[0.1, 0.0], [0.2, 0.0]]), np.array([[2.0, 3.0], [2.5, 3.5]]))
    pf = store.priced[0]
    wrong = PricedFigures(pf.eyes, pf.forwards, pf.scale, pf.packed[::-1], pf.error, pf.power_w)
    with pytest.raises(ValueError, match="frontier order"):
        dataclasses.replace(store, priced=[wrong])
    with pytest.raises(ValueError):
        PricedFigures(pf.eyes, pf.forwards, 0.0, pf.packed, pf.error, pf.power_w)


def test_another_frame_rate_reprices_the_prediction_as_the_stored_figures() -> None:
    cams = [((2.0, 2.0, 2.0), (1.0, 0.0, 0.0)), ((6.0, 2.0, 2.0), (1.0, 0.0, 0.0))]
    err = np.array([[0.05, 0.0], [0.05, 0.0]])
    pw = np.array([[4.0, 7.0], [4.0, 7.0]])
    store = _store(cams, err, pw, times=np.array([0.01, 0.02]))
    for fps in (30.0, 24.0):
        hit = store.lookup((3.0, 2.0, 2.0), direction=(1.0, 0.0, 0.0), power_budget=100.0, fps=fps)
        # both cameras agree, so the prediction is the stored figure at either rate
        assert hit.expected_power_w == pytest.approx(hit.power_w, rel=1e-9)
        assert hit.expected_error == pytest.approx(hit.error, abs=1e-12)


def test_playback_reports_the_prediction_for_the_camera() -> None:
    """What the HUD, Evaluate Path and the report's predicted columns show: the shown point's figures
    interpolated at the frame's camera (in transition too), not the worst over the pricing cameras."""
    cams = [((2.0, 2.0, 2.0), (1.0, 0.0, 0.0)), ((6.0, 2.0, 2.0), (1.0, 0.0, 0.0))]
    err = np.array([[0.08, 0.03, 0.0], [0.12, 0.05, 0.0]])
    pw = np.array([[3.0, 5.0, 9.0], [3.2, 5.5, 9.4]])
    store = _store(cams, err, pw, scale=2.0)
    driver = PlaybackDriver(store, period_s=2.0)

    def matrix(eye):
        m = np.eye(4)
        f = _unit([1.0, 0.0, 0.0])
        up = view_up(f)
        right = np.cross(f, up)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, -f, eye
        return m

    first = driver.step(matrix((2.0, 2.0, 2.0)), store.vfov, store.aspect, 0.0, "POWER", 6.0)
    assert first.predicted_error == pytest.approx(0.03, abs=1e-4)  # the sample camera's, not 0.05
    assert first.predicted_power_w == pytest.approx(5.0, abs=1e-3)
    # the budget falls: the filter moves towards the cheaper point over T, each shown point predicted here
    # a camera between the two, nearer the guard: the prediction moves towards the guard's figures
    between = driver.step(matrix((4.8, 2.0, 2.0)), store.vfov, store.aspect, 0.5, "POWER", 6.0)
    hit = store.lookup((4.8, 2.0, 2.0), matrix=matrix((4.8, 2.0, 2.0)), power_budget=6.0)
    w = hit.weights
    assert w[1] > w[0] > 0
    assert between.predicted_error == pytest.approx(w[0] * 0.03 + w[1] * 0.05, abs=1e-4)
    shown = {p.indices: p for p in store.budget_points(hit)}
    assert (between.predicted_error, between.predicted_power_w) == store.expected(
        hit, shown[between.active_indices])


def test_the_panels_path_summary_predicts_power_for_each_frames_camera() -> None:
    """The add-on panel's predicted power along a path is the mean of each frame's prediction for its
    camera, not of the stored worst figures."""
    from addon.core.playback_logic import predicted_path_summary
    from service.camera_path import CameraFrame
    from service.store.camera import look_matrix

    cams = [((2.0, 2.0, 2.0), (1.0, 0.0, 0.0)), ((6.0, 2.0, 2.0), (1.0, 0.0, 0.0))]
    store = _store(cams, np.array([[0.08, 0.0], [0.12, 0.0]]), np.array([[3.0, 9.0], [4.0, 9.8]]), scale=2.0)
    frames = [CameraFrame(i / 24, look_matrix((2.0 + 0.4 * i, 2.0, 2.0), (1.0, 0.0, 0.0)), store.vfov,
                          (64, 36)) for i in range(11)]
    s = predicted_path_summary(store, frames, "POWER", 5.0)
    hits = [store.lookup(f.matrix_world[:3, 3], matrix=f.matrix_world, fov=f.vfov, aspect=f.aspect,
                         power_budget=5.0) for f in frames]
    assert s["mean_power_w"] == pytest.approx(np.mean([h.expected_power_w for h in hits]))
    assert s["mean_power_w"] < np.mean([h.power_w for h in hits]) - 0.2  # the stored 4 W on every frame
