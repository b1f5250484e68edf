"""Runtime Pareto store: packing, frontier search, lookup edge cases, temporal filter, serialisation."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.octree import root_cube
from service.store import (
    FORMAT_VERSION,
    MAX_PARAMS,
    VIEW_FORWARD,
    VIEW_NAMES,
    Frontier,
    ParetoStore,
    StoredParameter,
    TemporalFilter,
    camera_rotation,
    pack_array,
    pack_indices,
    unpack_array,
    unpack_indices,
)

PARAMS = (
    StoredParameter("mode", ("under4", "under2", "1spp"), 2),
    StoredParameter("depth", (0, 1, 2, 3), 3),
    StoredParameter("scale", (0.7, 0.8, 0.9, 1.0), 3),
)


def _frontier(seed: int) -> Frontier:
    rng = np.random.default_rng(seed)
    n = 6
    idx = rng.integers(0, [3, 4, 4], size=(n, 3))
    power = np.sort(rng.uniform(0.5, 3.0, n))
    err = np.sort(rng.uniform(0.0, 0.2, n))[::-1]
    return Frontier.from_points(pack_array(idx), err, power)


def _store(subdivide: bool = False, root_min=(0.0, 0.0, 0.0), size: float = 2.0) -> ParetoStore:
    """A real store: root cube, optionally split once; every corner has its own frontiers per view."""
    depth = 1 if subdivide else 0
    side = 1 << depth
    coords = [(x, y, z) for z in range(side + 1) for y in range(side + 1) for x in range(side + 1)]
    if not subdivide:
        coords = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    frontiers = [_frontier(i) for i in range(len(coords) * 6)]
    views = np.arange(len(coords) * 6).reshape(-1, 6)
    children = [1] + [-1] * 8 if subdivide else [-1]
    return ParetoStore(PARAMS, np.asarray(root_min), size, depth, np.asarray(children), np.asarray(coords),
                       views, frontiers, vfov=math.radians(50), aspect=4 / 3)


# ---------------------------------------------------------------------------------------------- packing


@given(st.lists(st.integers(0, 15), min_size=0, max_size=MAX_PARAMS))
def test_pack_roundtrip(idx: list[int]) -> None:
    packed = pack_indices(idx)
    assert 0 <= packed < 2**32
    assert unpack_indices(packed, len(idx)) == tuple(idx)
    arr = np.asarray([idx], dtype=np.int64).reshape(1, len(idx))
    assert int(pack_array(arr)[0]) == packed
    assert unpack_array(pack_array(arr), len(idx)).tolist() == [idx]


def test_pack_layout_and_errors() -> None:
    assert pack_indices([1, 2, 3]) == 0x321
    assert pack_indices([15] * 8) == 0xFFFFFFFF
    with pytest.raises(ValueError):
        pack_indices([16])
    with pytest.raises(ValueError):
        pack_indices([-1])
    with pytest.raises(ValueError):
        pack_indices([0] * 9)
    with pytest.raises(ValueError):
        unpack_indices(0x100, 2)  # bits beyond the parameters


# --------------------------------------------------------------------------------------------- frontier


@given(st.lists(st.tuples(st.integers(0, 9), st.integers(0, 9)), min_size=1, max_size=30),
       st.floats(-1, 11), st.floats(-1, 11))
def test_frontier_search_equals_brute_force(pts: list[tuple[int, int]], pb: float, eb: float) -> None:
    e = [a / 10 for a, _ in pts]
    p = [float(b) for _, b in pts]
    fr = Frontier.from_points(range(len(pts)), e, p)
    # non-dominated, sorted
    assert np.all(np.diff(fr.power_w) > 0) and np.all(np.diff(fr.error) < 0)
    for ei, pi in zip(e, p, strict=True):
        assert any(fe <= ei and fp <= pi for fe, fp in zip(fr.error, fr.power_w, strict=True))
    i, inf = fr.under_power(pb)
    feas = [(ei, pi) for ei, pi in zip(e, p, strict=True) if pi <= pb]
    if feas:
        assert not inf and fr.power_w[i] <= pb and fr.error[i] == min(f[0] for f in feas)
    else:
        assert inf and i == 0
    j, inf = fr.under_error(eb)
    feas = [(ei, pi) for ei, pi in zip(e, p, strict=True) if ei <= eb]
    if feas:
        assert not inf and fr.error[j] <= eb and fr.power_w[j] == min(f[1] for f in feas)
    else:
        assert inf and j == len(fr) - 1


# ------------------------------------------------------------------------------------------------ lookup


def test_lookup_inside_picks_nearest_corner_and_view() -> None:
    s = _store()
    r = s.lookup([0.2, 0.3, 1.1], direction=[1, 0, 0], power_budget=10.0)
    pos = s.corner_positions()[r.corner]
    assert np.allclose(pos, [0, 0, 2]) and not r.clamped and VIEW_NAMES[r.view] == "+X"
    fr = s.frontier(r.corner, r.view)
    assert r.packed == int(fr.packed[-1]) and r.error == pytest.approx(fr.error[-1])
    assert r.indices == unpack_indices(r.packed, 3)
    assert set(r.settings) == {"mode", "depth", "scale"}


@pytest.mark.parametrize("view", range(6))
def test_frustum_face_for_each_axis(view: int) -> None:
    s = _store()
    r = s.lookup([1.0, 1.0, 1.0], direction=VIEW_FORWARD[view], error_budget=1.0)
    assert r.view == view
    # a Blender matrix looking the same way gives the same face
    rot = camera_rotation(direction=VIEW_FORWARD[view])
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = 1.0
    assert s.lookup([1, 1, 1], matrix=m, error_budget=1.0).view == view


def test_frustum_face_takes_the_largest_share() -> None:
    s = _store()
    c = [1.0, 1.0, 1.0]
    assert VIEW_NAMES[s.lookup(c, direction=[1, 0.6, 0], power_budget=5.0).view] == "+X"
    assert VIEW_NAMES[s.lookup(c, direction=[0.6, 1, 0], power_budget=5.0).view] == "+Y"
    # looking 60 degrees up with a 30 degree fov: the whole frustum lies above 45 degrees
    up = [math.cos(math.radians(60)), 0, math.sin(math.radians(60))]
    assert VIEW_NAMES[s.lookup(c, direction=up, fov=math.radians(30), power_budget=5.0).view] == "+Z"
    # a 20 degree tilt keeps a narrow frustum on the horizontal view
    tilt = [0, -math.cos(math.radians(20)), -math.sin(math.radians(20))]
    assert VIEW_NAMES[s.lookup(c, direction=tilt, fov=math.radians(30), power_budget=5.0).view] == "-Y"


@pytest.mark.parametrize("pos,clamped", [
    ([-1, 1, 1], True), ([5, 5, 5], True), ([1, 1, -0.001], True),
    ([0, 0, 0], False), ([2, 2, 2], False), ([2, 1, 1], False), ([0, 2, 0], False), ([1, 1, 2], False),
])
def test_lookup_outside_faces_and_corners(pos, clamped: bool) -> None:
    for s in (_store(), _store(subdivide=True)):
        r = s.lookup(pos, direction=[0, 1, 0], power_budget=2.0)
        assert r.clamped is clamped
        q = np.clip(pos, 0, 2)
        dists = np.linalg.norm(s.corner_positions() - q, axis=1)
        leaf_corners = s.leaf_corners(r.leaf)
        assert dists[r.corner] == pytest.approx(dists[leaf_corners].min())


def test_lookup_finds_the_leaf_of_a_subdivided_root() -> None:
    s = _store(subdivide=True)
    r = s.lookup([1.6, 0.1, 1.7], direction=[0, 0, -1], power_budget=1.0)
    assert r.leaf == 1 + (1 | 4)
    assert np.allclose(s.corner_positions()[r.corner], [2, 0, 2])


@pytest.mark.parametrize("positions", [
    [[1.0, 2.0, 3.0]] * 5,  # all points equal
    [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [2.0, 0.0, 0.0]],  # a straight line along x
])
def test_degenerate_paths_get_a_cube(positions) -> None:
    lo, size = root_cube(positions, 0.1, 1.0)
    assert size > 0
    p = np.asarray(positions)
    assert np.all(p >= lo) and np.all(p <= lo + size)
    s = _store(root_min=lo, size=size)
    for q in positions:
        r = s.lookup(q, direction=[1, 0, 0], power_budget=1.5)
        assert not r.clamped


def test_budget_below_and_above_the_frontier() -> None:
    s = _store()
    args = dict(position=[1, 1, 1], direction=[1, 0, 0])
    fr = s.frontier(s.lookup(**args, power_budget=1.0).corner, 0)
    low = s.lookup(**args, power_budget=float(fr.power_w.min()) / 2)
    assert low.infeasible and low.power_w == pytest.approx(fr.power_w.min())
    high = s.lookup(**args, power_budget=1e9)
    assert not high.infeasible and high.error == pytest.approx(fr.error.min())
    tight = s.lookup(**args, error_budget=float(fr.error.min()) / 2 - 1e-3)
    assert tight.infeasible and tight.error == pytest.approx(fr.error.min())
    loose = s.lookup(**args, error_budget=1.0)
    assert not loose.infeasible and loose.power_w == pytest.approx(fr.power_w.min())


def test_lookup_rejects_bad_input() -> None:
    s = _store()
    with pytest.raises(ValueError):
        s.lookup([0, 0, 0], direction=[1, 0, 0])
    with pytest.raises(ValueError):
        s.lookup([0, 0, 0], direction=[1, 0, 0], power_budget=1, error_budget=1)
    with pytest.raises(ValueError):
        s.lookup([np.nan, 0, 0], direction=[1, 0, 0], power_budget=1)
    with pytest.raises(ValueError):
        s.lookup([0, 0, 0], direction=[0, 0, 0], power_budget=1)
    with pytest.raises(ValueError):
        s.lookup([0, 0, 0], direction=[1, 0, 0], fov=4.0, power_budget=1)
    # huge but finite orientations are fine (scale-free), not an overflow
    assert s.lookup([1, 1, 1], direction=[1e308, 0, -1e308], power_budget=1).view in (0, 5)
    m = np.eye(4) * 1e307
    m[3, 3] = 1
    assert VIEW_NAMES[s.lookup([1, 1, 1], matrix=m, power_budget=1).view] == "-Z"
    assert s.lookup([1, 1, 1], direction=[1e-200, 0, 0], power_budget=1).view == 0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-3, 5), min_size=3, max_size=3), st.lists(st.floats(-1, 1), min_size=3,
       max_size=3), st.floats(0.0, 4.0))
def test_lookup_invariants(pos, d, budget) -> None:
    if np.linalg.norm(d) < 1e-3:
        d = [1.0, 0.0, 0.0]
    s = _STORE
    r = s.lookup(pos, direction=d, power_budget=budget)
    assert r.clamped == bool(np.any((np.asarray(pos) < 0) | (np.asarray(pos) > 2)))
    fr = s.frontier(r.corner, r.view)
    if r.infeasible:
        assert r.power_w == pytest.approx(fr.power_w.min()) and fr.power_w.min() > budget
    else:
        assert r.power_w <= budget + 1e-9
        assert r.error == pytest.approx(fr.error[fr.power_w <= budget + 1e-12].min())


_STORE = _store(subdivide=True)


# ----------------------------------------------------------------------------------------- serialisation


def test_json_roundtrip_and_size() -> None:
    s = _store(subdivide=True)
    text = s.to_json()
    doc = json.loads(text)
    assert doc["version"] == FORMAT_VERSION and doc["views"] == list(VIEW_NAMES)
    t = ParetoStore.from_json(text)
    assert t.to_json() == text
    for a, b in zip(s.frontiers, t.frontiers, strict=True):
        assert np.array_equal(a.packed, b.packed)
        assert np.allclose(a.error, b.error, atol=1.0 / 65535)
        assert np.allclose(a.power_w, b.power_w, atol=a.power_w.max() / 65535 + 1e-12)
    r1 = s.lookup([0.3, 1.2, 0.5], direction=[0, -1, 0.2], power_budget=2.0)
    r2 = t.lookup([0.3, 1.2, 0.5], direction=[0, -1, 0.2], power_budget=2.0)
    assert (r1.corner, r1.view) == (r2.corner, r2.view)
    assert s.stats()["size_bytes"] == len(text)


@pytest.mark.parametrize("mutate", [
    lambda d: d.update(version=99),
    lambda d: d.update(format="x"),
    lambda d: d.pop("node_splits"),
    lambda d: d.update(frontier_error="<u2:!!"),
    lambda d: d.update(children="<i4:" + "AAAAAA=="),
])
def test_corrupt_store_is_rejected(mutate) -> None:
    d = json.loads(_store().to_json())
    mutate(d)
    with pytest.raises(ValueError):
        ParetoStore.from_json(json.dumps(d))


# ------------------------------------------------------------------------------------------ temporal filter


def test_filter_endpoints_and_midpoint() -> None:
    f = TemporalFilter(2.0)
    assert f.update([0, 0, 0], 10.0) == (0, 0, 0)
    assert f.update([4, 2, 1], 11.0) == (0, 0, 0)  # t = 0: the old settings
    assert f.update([4, 2, 1], 12.0) == (2, 1, 1)  # t = T/2: round(0.5 * new), halves round up
    assert f.update([4, 2, 1], 13.0) == (4, 2, 1)  # t = T
    assert f.update([4, 2, 1], 50.0) == (4, 2, 1)


def test_filter_change_mid_transition_starts_from_shown() -> None:
    f = TemporalFilter(2.0)
    f.update([0], 0.0)
    f.update([8], 1.0)
    assert f.update([8], 2.0) == (4,)
    assert f.update([0], 2.0) == (4,)  # new target: continue from what is shown
    assert f.update([0], 3.0) == (2,)
    assert f.update([0], 4.0) == (0,)


def test_filter_time_backwards_and_zero_period() -> None:
    f = TemporalFilter(2.0)
    f.update([0], 5.0)
    f.update([6], 5.0)
    assert f.update([6], 1.0) == (6,)  # scrubbing back snaps to the target
    g = TemporalFilter(0.0)
    g.update([0], 0.0)
    assert g.update([3], 0.0) == (3,)
    with pytest.raises(ValueError):
        TemporalFilter(-1)
    with pytest.raises(ValueError):
        g.update([1], math.nan)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.lists(st.integers(0, 15), min_size=3, max_size=3), st.floats(0, 1.5)),
                min_size=1, max_size=12), st.floats(0.1, 5.0))
def test_filter_values_stay_between_old_and_new(steps, period) -> None:
    f = TemporalFilter(period)
    now = 0.0
    shown = None
    prev_target = None
    seen = []
    for target, dt in steps:
        now += dt
        prev = shown
        shown = f.update(target, now)
        seen.append(target)
        lo, hi = np.min(seen, axis=0), np.max(seen, axis=0)
        assert all(lo[i] <= v <= hi[i] for i, v in enumerate(shown))  # valid, never overshoots
        if prev is not None and target == prev_target:
            # same target: every index keeps moving towards it
            for s, p, t in zip(shown, prev, target, strict=True):
                assert abs(s - t) <= abs(p - t)
        prev_target = target
    # hold the last target for T: it is reached
    assert f.update(steps[-1][0], now + period) == tuple(steps[-1][0])


# ------------------------------------------------------------------------ aimed sample views (version 2)

_unit_dirs = st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 3).filter(
    lambda v: max(abs(c) for c in v) > 1e-3)


@given(_unit_dirs)
def test_face_of_is_a_valid_face_and_matches_a_narrow_frustum(v) -> None:
    from service.store import face_of

    k = face_of(v)
    assert 0 <= k < 6
    # the face's axis is the direction's largest component, with its sign
    d = np.asarray(v) / np.linalg.norm(v)
    assert float(d @ VIEW_FORWARD[k]) == pytest.approx(float(np.abs(d).max()))
    # lookup's frustum vote agrees for a narrow frustum away from cone borders
    srt = np.sort(np.abs(d))
    if srt[2] - srt[1] > 0.05:
        s = _store()
        assert s.choose_view(camera_rotation(direction=d), math.radians(1.0), 1.0) == k


@given(st.lists(_unit_dirs, min_size=1, max_size=12))
def test_quantised_directions_are_unit_and_close(vs) -> None:
    from service.store import quantise_directions

    d = np.asarray(vs, dtype=np.float64)
    q = quantise_directions(d)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    assert np.all((q * u).sum(axis=1) > math.cos(math.radians(1.0)))  # within a degree
    assert np.array_equal(quantise_directions(q), q)  # stable: a reloaded store re-encodes identically


def _aimed_store() -> ParetoStore:
    s = _store(subdivide=True)
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(s.corner_coords.shape[0], 6, 3))
    s.view_dirs = dirs
    s.__post_init__()
    return s


def test_view_dirs_roundtrip_and_old_version_loads_as_axis_views() -> None:
    from service.store import quantise_directions

    s = _aimed_store()
    text = s.to_json()
    doc = json.loads(text)
    assert doc["version"] == FORMAT_VERSION and "view_dirs" in doc
    t = ParetoStore.from_json(text)
    assert t.to_json() == text
    assert np.allclose(t.view_dirs, quantise_directions(s.view_dirs))
    assert np.allclose(np.linalg.norm(t.view_dirs, axis=2), 1.0)
    eye, f, up = t.sample_camera(4, 2)
    assert np.allclose(f, t.view_dirs[4, 2]) and abs(float(f @ up)) < 0.96
    assert np.allclose(eye, t.corner_positions()[4])
    # lookup is unchanged by the sample directions: same corner, face and settings
    a = _store(subdivide=True).lookup([0.3, 1.2, 0.5], direction=[0, -1, 0.2], power_budget=2.0)
    b = t.lookup([0.3, 1.2, 0.5], direction=[0, -1, 0.2], power_budget=2.0)
    assert (a.corner, a.view, a.packed) == (b.corner, b.view, b.packed)
    # a version-1 document (no view_dirs) still loads, with axis sample views
    old = _store(subdivide=True).to_dict()
    old["version"] = 1
    v1 = ParetoStore.from_dict(old)
    assert v1.view_dirs is None
    for v in range(6):
        assert np.array_equal(v1.sample_direction(0, v), VIEW_FORWARD[v])
        assert np.array_equal(v1.sample_camera(0, v)[2], [0, 0, 1] if v < 4 else [0, 1, 0])
    bad = json.loads(text)
    bad["view_dirs"] = bad["view_dirs"][:-4]
    with pytest.raises(ValueError):
        ParetoStore.from_dict(bad)
    with pytest.raises(ValueError):
        ParetoStore(PARAMS, np.zeros(3), 2.0, 0, np.asarray([-1]),
                    np.asarray([(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]),
                    np.zeros((8, 6), dtype=np.int64), [_frontier(0)], view_dirs=np.zeros((8, 6, 3)))


def test_frontier_cameras_roundtrip_and_locate_matches_lookup() -> None:
    """Version 3: one sample camera per frontier (path-sampled stores); every face sharing a frontier
    reports its camera; `locate` is the lookup's (corner, view) without a budget."""
    from service.store import quantise_directions, quantise_eyes

    s = _store(subdivide=True)
    rng = np.random.default_rng(5)
    nf = len(s.frontiers)
    eyes = s.root_min + rng.uniform(0, s.root_size, size=(nf, 3))
    s.frontier_dirs = rng.normal(size=(nf, 3))
    s.frontier_eyes = eyes
    s.__post_init__()
    text = s.to_json()
    doc = json.loads(text)
    assert doc["version"] == FORMAT_VERSION and "frontier_dirs" in doc and "frontier_eyes" in doc
    t = ParetoStore.from_json(text)
    assert t.to_json() == text  # decoding and re-encoding is stable
    assert np.allclose(t.frontier_eyes, quantise_eyes(eyes, s.root_min, s.root_size), atol=1e-12)
    assert np.max(np.abs(t.frontier_eyes - eyes)) <= s.root_size / 65535
    assert np.allclose(t.frontier_dirs, quantise_directions(s.frontier_dirs, fine=True))
    for c in range(t.corner_coords.shape[0]):
        for v in range(6):
            eye, f, up = t.sample_camera(c, v)
            fid = int(t.corner_views[c, v])
            assert np.array_equal(eye, t.frontier_eyes[fid]) and np.array_equal(f, t.frontier_dirs[fid])
            assert abs(float(f @ up)) < 0.96
    for pos, d in (([0.3, 1.2, 0.5], [0, -1, 0.2]), ([1.9, 0.1, 1.0], [1, 0.1, -0.3])):
        r = t.lookup(pos, direction=d, error_budget=0.05)
        assert t.locate(pos, direction=d) == (r.corner, r.view)
    bad = json.loads(text)
    bad["frontier_eyes"] = bad["frontier_eyes"][:-4]
    with pytest.raises(ValueError):
        ParetoStore.from_dict(bad)
    with pytest.raises(ValueError):  # both or neither
        ParetoStore(PARAMS, s.root_min, s.root_size, s.lattice_depth, s.children, s.corner_coords,
                    s.corner_views, s.frontiers, frontier_dirs=np.ones((nf, 3)))
    with pytest.raises(ValueError):  # one per frontier
        ParetoStore(PARAMS, s.root_min, s.root_size, s.lattice_depth, s.children, s.corner_coords,
                    s.corner_views, s.frontiers, frontier_dirs=np.ones((nf + 1, 3)),
                    frontier_eyes=np.ones((nf + 1, 3)))


@given(st.lists(_unit_dirs, min_size=1, max_size=12))
def test_fine_directions_are_within_a_hundredth_of_a_degree(vs) -> None:
    from service.store import quantise_directions

    d = np.asarray(vs, dtype=np.float64)
    q = quantise_directions(d, fine=True)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    assert np.all((q * u).sum(axis=1) > math.cos(math.radians(0.01)))
    assert np.array_equal(quantise_directions(q, fine=True), q)


@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-5, 5)), min_size=1,
                max_size=20), st.floats(0.0, 0.5))
def test_root_cube_resting_on_the_path_still_contains_it(pts, pad) -> None:
    p = np.asarray(pts)
    lo, size = root_cube(p, pad, 1.0)
    lo2, size2 = root_cube(p, pad, 1.0, rest_on_path=True)
    assert size2 == size and np.array_equal(lo2[:2], lo[:2])
    assert np.all(p >= lo2 - 1e-9) and np.all(p <= lo2 + size2 + 1e-9)
    assert lo2[2] >= lo[2]
    assert lo2[2] >= p[:, 2].min() - pad * np.ptp(p[:, 2]) - 1e-9


# ------------------------------------------------------------------------------------------ frame times


def _timed_store(times: list[np.ndarray], fps: float = 30.0) -> ParetoStore:
    """The one-cube store with frontier i's frame times ``times[i % len(times)]`` (frontiers unchanged)."""
    s = _store()
    frontiers = [Frontier(f.packed, f.error, f.power_w, times[i % len(times)][: len(f)])
                 for i, f in enumerate(s.frontiers)]
    return ParetoStore(s.parameters, s.root_min, s.root_size, s.lattice_depth, s.children, s.corner_coords,
                       s.corner_views, frontiers, vfov=s.vfov, aspect=s.aspect, fps=fps)


def test_frontier_of_settings_that_meet_the_frame_rate() -> None:
    packed, err = [1, 2, 3, 4], [0.0, 0.01, 0.05, 0.2]
    power = [0.7, 0.9, 0.5, 0.3]  # the max-quality setting draws less than the next: it runs slowly
    times = [0.75, 0.12, 0.01, 0.001]
    fr = Frontier.from_points(packed, err, power, times, fps=30.0)
    # the meeting tier, then the slow tier: setting 2 misses 30 fps and is dominated by setting 1 (which
    # also misses it and is more accurate than every setting that meets it)
    assert fr.packed.tolist() == [4, 3, 1] and fr.frame_time_s.tolist() == [0.001, 0.01, 0.75]
    fast, slow_tier = fr.tiers(30.0)
    assert fast.packed.tolist() == [4, 3] and fr.meeting(30.0).packed.tolist() == [4, 3]
    assert slow_tier is not None and slow_tier.packed.tolist() == [1]
    assert fr.tiers(1.0) == (fr, None)  # every point meets 1 fps: one tier
    # without frame times (or when no setting keeps up) the slow settings stay on the frontier
    assert Frontier.from_points(packed, err, power).packed.tolist() == [4, 3, 1]
    slow = Frontier.from_points(packed, err, power, [1.0] * 4, fps=30.0)
    assert slow.packed.tolist() == [4, 3, 1] and slow.meeting(30.0) is slow
    with pytest.raises(ValueError, match="fps"):
        Frontier.from_points(packed, err, power, times)
    with pytest.raises(ValueError, match="frame times"):
        Frontier.from_points(packed, err, power, [0.1, -1.0, 0.1, 0.1], fps=30.0)
    with pytest.raises(ValueError, match="frame times"):
        Frontier(np.asarray([1], dtype=np.uint32), np.zeros(1), np.ones(1), np.asarray([math.nan]))


@settings(max_examples=60, deadline=None)
@given(times=st.lists(st.lists(st.floats(0.0, 5.0), min_size=6, max_size=6), min_size=1, max_size=4),
       fps=st.sampled_from([30.0, 24.0, 60.0, 10.0, 29.97]), edge=st.booleans())
def test_frame_times_round_trip_on_their_side_of_the_frame_period(times: list[list[float]], fps: float,
                                                                  edge: bool) -> None:
    t = [np.asarray(v) for v in times]
    if edge:  # frame times exactly on, and one rounding step either side of, the frame period
        t[0][:3] = [1.0 / fps, np.nextafter(1.0 / fps, 0.0), np.nextafter(1.0 / fps, 1.0)]
    s = _timed_store(t, fps)
    text = s.to_json()
    doc = json.loads(text)
    assert doc["version"] == FORMAT_VERSION == 6 and "frontier_frame_time" in doc
    back = ParetoStore.from_json(text)
    assert back.frame_times_known and back.to_json() == text
    step = doc["frame_time_scale"] / 65535
    for a, b in zip(s.frontiers, back.frontiers, strict=True):
        assert np.all(np.abs(a.frame_time_s - b.frame_time_s) <= step * (1 + 1e-9))
        for x, y in zip(a.frame_time_s, b.frame_time_s, strict=True):
            assert (x <= 1.0 / fps) == (y <= 1.0 / fps)  # still on its side of the frame period
            if x > 1.0 / fps:
                assert y >= x or y == pytest.approx(x, rel=1e-12)  # never optimistic for a slow frame
    assert back.stats()["frame_times_known"]


def test_lookup_marks_the_frame_rate_and_never_picks_a_slow_setting_when_a_fast_one_exists() -> None:
    fast_and_slow = np.asarray([0.001, 0.01, 0.02, 0.03, 0.2, 0.9])  # the last two miss 30 fps
    slow_and_cheap = np.asarray([0.9, 0.2, 0.01, 0.02, 0.001, 0.03])  # slow settings at the cheap end
    all_slow = np.full(6, 0.5)
    s = _timed_store([fast_and_slow, slow_and_cheap, all_slow])
    budgets = ({"power_budget": 1e3}, {"error_budget": 0.0}, {"power_budget": 0.0}, {"error_budget": 1.0})
    for budget in budgets:
        for direction in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]):
            hit = s.lookup([0.2, 0.2, 0.2], direction=direction, **budget)
            fr = s.frontiers[int(s.corner_views[hit.corner, hit.view])]
            points = zip(fr.packed, fr.power_w, fr.error, fr.frame_time_s, strict=True)
            t = next(ft for pk, pw, e, ft in points if (pk, pw, e) == (hit.packed, hit.power_w, hit.error))
            assert hit.frame_time_s == t
            if (fr.frame_time_s <= 1 / 30).any():
                assert hit.meets_fps is True and hit.fps == 30.0 and t <= 1 / 30
            else:  # no setting keeps up: the pick says so, with the frame rate it reaches
                assert hit.meets_fps is False and hit.fps == pytest.approx(1 / t)
    # a store without frame times (format before 4): unknown, and the old answers
    old = _store()
    hit = old.lookup([0.2, 0.2, 0.2], direction=[1, 0, 0], power_budget=1e3)
    assert (hit.frame_time_s, hit.fps, hit.meets_fps) == (None, None, None)
    assert not old.frame_times_known and "frontier_frame_time" not in old.to_dict()


def test_stores_before_frame_times_still_load() -> None:
    """A version-3 document (no frame times) loads with frame times unknown; a store mixing frontiers
    with and without them, or with a bad scale or length, is refused."""
    doc = _store(subdivide=True).to_dict()
    doc["version"] = 3
    v3 = ParetoStore.from_dict(doc)
    assert not v3.frame_times_known and v3.lookup([0.3, 0.3, 0.3], direction=[0, 1, 0],
                                                  error_budget=0.1).meets_fps is None
    timed = _timed_store([np.full(6, 0.01)]).to_dict()
    for key, value in (("frame_time_scale", 0.0), ("frame_time_scale", math.inf),
                       ("frontier_frame_time", "<u2:AAA=")):
        bad = dict(timed, **{key: value})
        with pytest.raises(ValueError):
            ParetoStore.from_dict(bad)
    s = _store()
    mixed = [Frontier(f.packed, f.error, f.power_w, np.zeros(len(f)) if i else None)
             for i, f in enumerate(s.frontiers)]
    with pytest.raises(ValueError, match="every frontier"):
        ParetoStore(s.parameters, s.root_min, s.root_size, 0, s.children, s.corner_coords, s.corner_views,
                    mixed)
    with pytest.raises(ValueError, match="fps"):
        ParetoStore(s.parameters, s.root_min, s.root_size, 0, s.children, s.corner_coords, s.corner_views,
                    s.frontiers, fps=0.0)


def test_the_store_says_which_display_its_figures_hold_for() -> None:
    """Display-priced figures name their display (and a render of another size beside it); preview
    figures, and stores from before display pricing (all preview), are never called a display's."""
    from dataclasses import replace

    from service.store import FiguresSize

    base = _store()
    display = replace(base, meta={"figures_resolution": [640, 360], "display_pricing": "tiles:ssim"})
    assert display.figures == FiguresSize("display", (640, 360)) and display.figures.display == (640, 360)
    assert display.figures.label() == "for a 640x360 display"
    assert display.figures.label((1280, 720)) == "for a 640x360 display, not this scene's 1280x720"
    assert display.figures.short((1280, 720)) == "640x360, not 1280x720"
    assert display.figures.short((640, 360)) == display.figures.short() == "640x360"
    for meta in ({"figures_resolution": [64, 36], "display_pricing": "preview"},
                 {"figures_resolution": [64, 36]}, {"eval_resolution": [64, 36]}):
        fig = replace(base, meta=meta).figures
        assert fig == FiguresSize("preview", (64, 36)) and fig.display is None
        assert "display" not in fig.label((1280, 720)) and fig.short((1280, 720)) == "preview 64x36"
    unknown = replace(base, meta={}).figures
    assert unknown.kind == "unknown" and unknown.resolution is None and unknown.short() == "size unknown"
    # round trip through the store document
    assert ParetoStore.from_json(display.to_json()).figures == display.figures


@pytest.mark.parametrize("bad", [[0, 360], [640], "640x360", [True, 360], [640.5, 360], [math.inf, 360],
                                 [math.nan, 360], [640, 1], None])
def test_a_store_with_a_bad_figures_size_is_refused_on_reading(bad) -> None:
    from dataclasses import replace

    base = _store()
    meta = {"figures_resolution": bad} if bad is not None else {"eval_resolution": [64, -1]}
    with pytest.raises(ValueError, match="resolution"):
        replace(base, meta=meta)
    doc = json.loads(base.to_json())
    doc["meta"] = meta
    with pytest.raises(ValueError, match="resolution"):
        ParetoStore.from_json(json.dumps(doc))
