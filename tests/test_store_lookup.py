"""The fast store lookup gives exactly the answers of the lookup it replaced (``tests/store_reference.py``)
over random stores, poses and budgets: inside and outside the root, on cell middles and face edges
(ties), matrices with any scale, infeasible budgets, budgets equal to frontier points, single-point
frontiers, and frame times (none, all or some settings keeping up with the store's frame rate, on the
frame period itself; frontiers with a slow tier, format 5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.store import Frontier, ParetoStore, StoredParameter, pack_indices
from service.store.camera import VFOV_MAX
from tests.store_reference import ReferenceLookup

PARAMS = (StoredParameter("a", (0, 1, 2), 2), StoredParameter("b", (0.5, 1.0), 1),
          StoredParameter("c", ("x", "y", "z", "w"), 3))


def _octree(splits: list[bool], depth: int) -> tuple[list[int], list[tuple[tuple[int, int, int], int]]]:
    """Children array (eight consecutive children per split node) and each node's (origin, size)."""
    side = 1 << depth
    nodes = [((0, 0, 0), side)]
    children = [-1]
    level = [0]
    draw = iter(splits)
    for _ in range(depth):
        nxt = []
        for n in level:
            if not next(draw, False):
                continue
            (x, y, z), s = nodes[n]
            h = s // 2
            children[n] = len(nodes)
            for k in range(8):
                nodes.append(((x + h * (k & 1), y + h * ((k >> 1) & 1), z + h * ((k >> 2) & 1)), h))
                children.append(-1)
                nxt.append(len(nodes) - 1)
        level = nxt
    return children, nodes


@st.composite
def stores(draw: st.DrawFn) -> ParetoStore:
    depth = draw(st.integers(0, 3))
    children, nodes = _octree(draw(st.lists(st.booleans(), min_size=0, max_size=80)), depth)
    corners: dict[tuple[int, int, int], int] = {}
    for n, ((x, y, z), s) in enumerate(nodes):
        if children[n] == -1:
            for k in range(8):
                xyz = (x + s * (k & 1), y + s * ((k >> 1) & 1), z + s * ((k >> 2) & 1))
                corners.setdefault(xyz, len(corners))
    n_frontiers = draw(st.integers(1, 12))
    fps = draw(st.sampled_from([30.0, 24.0, 60.0, 29.97]))
    # frame times unknown (before format 4), any mix of them on a frontier, or the two tiers of format 5
    timed = draw(st.sampled_from([None, "any", "tiers"]))
    period = 1.0 / fps
    times = st.one_of(st.floats(0.0, 0.2), st.sampled_from(
        [period, float(np.nextafter(period, 0.0)), float(np.nextafter(period, 1.0)), 0.0, 5.0]))
    frontiers = []
    for _ in range(n_frontiers):
        n = draw(st.integers(1, 6))  # single-point frontiers included
        packed = [pack_indices([draw(st.integers(0, 2)), draw(st.integers(0, 1)), draw(st.integers(0, 3))])
                  for _ in range(n)]
        err = draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n))
        pw = draw(st.lists(st.floats(0.0, 20.0), min_size=n, max_size=n))
        if timed == "tiers":  # the meeting tier, then the accurate settings that miss the rate
            fr = Frontier.from_points(packed, err, pw, draw(st.lists(times, min_size=n, max_size=n)), fps)
        else:
            fr = Frontier.from_points(packed, err, pw)
        if timed == "any":  # any mix of settings that meet and miss the frame rate, wherever they lie on it
            t = draw(st.lists(times, min_size=len(fr), max_size=len(fr)))
            fr = Frontier(fr.packed, fr.error, fr.power_w, np.asarray(t))
        frontiers.append(fr)
    n_views = 6 * len(corners)
    views = draw(st.lists(st.integers(0, n_frontiers - 1), min_size=n_views, max_size=n_views))
    coords = np.zeros((len(corners), 3), dtype=np.int64)
    for xyz, i in corners.items():
        coords[i] = xyz
    root_min = draw(st.tuples(*[st.floats(-100, 100)] * 3))
    size = draw(st.sampled_from([1.0, 2.0, 20.0, 0.3, 123.456]))
    return ParetoStore(PARAMS, np.asarray(root_min), size, depth, np.asarray(children), coords,
                       np.asarray(views).reshape(-1, 6), frontiers, vfov=draw(st.floats(0.1, 2.5)),
                       aspect=draw(st.sampled_from([16 / 9, 4 / 3, 1.0, 0.5])), fps=fps)


AXES = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (-1, 0, 0), (1, 1, 0), (1, -1, 0), (1, 1, 1), (-1, 1, -1),
        (0, 1, 1), (0, 0, -1), (1, 0, 1e-9), (3, 3, 1e-12)]


@st.composite
def orientations(draw: st.DrawFn) -> dict:
    kind = draw(st.sampled_from(["direction", "axis", "up", "matrix", "matrix3"]))
    vec = st.tuples(*[st.floats(-1e3, 1e3)] * 3)
    if kind == "direction":
        return {"direction": draw(vec)}
    if kind == "axis":  # face edges and corners of the view cube: exact ties between rays' faces
        return {"direction": draw(st.sampled_from(AXES))}
    if kind == "up":
        return {"direction": draw(vec), "up": draw(st.sampled_from([(0, 0, 1), (0, 1, 0), (1, 2, 3)]))}
    q = np.asarray(draw(st.tuples(*[st.floats(-1, 1)] * 4)))
    if float(np.linalg.norm(q)) < 1e-3:
        q = np.array([1.0, 0.0, 0.0, 0.0])
    w, x, y, z = q / np.linalg.norm(q)
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    if draw(st.booleans()):  # snap to a quarter turn: axis-aligned frusta
        r = np.round(r)
    r = r * np.asarray(draw(st.sampled_from([(1, 1, 1), (2, 0.5, 3), (1e150, 1e150, 1e150), (1e-150, 1, 7)])))
    if kind == "matrix3":
        return {"matrix": r}
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, draw(vec)
    return {"matrix": m.tolist() if draw(st.booleans()) else m}


@st.composite
def positions(draw: st.DrawFn, store: ParetoStore) -> list[float]:
    lo, size = store.root_min, store.root_size
    if draw(st.booleans()):  # on the lattice's cell middles and planes: nearest-corner ties
        k = 1 << (store.lattice_depth + 1)
        u = [draw(st.integers(-1, k + 1)) / k for _ in range(3)]
    else:
        u = draw(st.tuples(*[st.floats(-0.5, 1.5)] * 3))
    return [float(lo[i] + size * u[i]) for i in range(3)]


@st.composite
def budgets(draw: st.DrawFn, store: ParetoStore) -> dict:
    fr = draw(st.sampled_from(store.frontiers))
    if draw(st.booleans()):
        exact = draw(st.booleans())  # a budget equal to a frontier point, or anywhere (infeasible too)
        value = float(draw(st.sampled_from(list(fr.power_w)))) if exact else draw(st.floats(0.0, 25.0))
        return {"power_budget": value}
    exact = draw(st.booleans())
    value = float(draw(st.sampled_from(list(fr.error)))) if exact else draw(st.floats(0.0, 1.0))
    return {"error_budget": value}


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_fast_lookup_equals_the_reference(data: st.DataObject) -> None:
    store = data.draw(stores())
    ref = ReferenceLookup(store)
    for _ in range(12):
        pose = data.draw(orientations())
        fov = data.draw(st.one_of(st.none(), st.floats(0.01, VFOV_MAX, exclude_max=True),  # the camera limits
                                  st.sampled_from([0.6911, math.pi / 2])))
        aspect = data.draw(st.one_of(st.none(), st.floats(0.2, 5.0), st.just(1.0)))
        where = data.draw(positions(store))
        budget = data.draw(budgets(store))
        try:
            want = ref.lookup(where, fov=fov, aspect=aspect, **pose, **budget)
        except ValueError as exc:
            with pytest.raises(ValueError, match=str(exc)[:20]):
                store.lookup(where, fov=fov, aspect=aspect, **pose, **budget)
            continue
        got = store.lookup(where, fov=fov, aspect=aspect, **pose, **budget)
        assert (got.indices, got.packed, got.settings, got.power_w, got.error, got.clamped, got.infeasible,
                got.corner, got.view, got.leaf, got.frame_time_s, got.fps, got.meets_fps) == want
        if got.meets_fps is False:  # a setting that misses the frame rate only when none meets it
            fr = store.frontiers[int(store.corner_views[got.corner, got.view])]
            assert not np.any(fr.frame_time_s <= 1.0 / store.fps)
        want_cv = ref.locate(where, fov=fov, aspect=aspect, **pose)
        assert store.locate(where, fov=fov, aspect=aspect, **pose) == want_cv


def test_the_benchmark_stores_answer_as_before() -> None:
    """The stores of bench_lookup and bench_playback along their own query streams."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import bench_lookup
    import bench_playback

    rng = np.random.default_rng(7)
    store = bench_lookup.generated_store()
    ref = ReferenceLookup(store)
    for _ in range(2000):
        p = store.root_min + store.root_size * rng.uniform(-0.1, 1.1, 3)
        d = rng.normal(size=3)
        b = float(rng.uniform(0.0, 3.5))
        kw = {"power_budget": b} if rng.random() < 0.5 else {"error_budget": b / 15}
        got = store.lookup(p, direction=d, **kw)
        want = ref.lookup(p, direction=d, **kw)
        assert (got.indices, got.packed, got.power_w, got.error, got.corner, got.view) == (
            want[0], want[1], want[3], want[4], want[7], want[8])
    store = bench_playback.paper_sized_store()
    ref = ReferenceLookup(store)
    for m in bench_playback.flight(600):
        got = store.lookup(m[:3, 3], matrix=m, fov=0.69, aspect=16 / 9, error_budget=0.02)
        want = ref.lookup(m[:3, 3], matrix=m, fov=0.69, aspect=16 / 9, error_budget=0.02)
        assert (got.packed, got.corner, got.view, got.leaf) == (want[1], want[7], want[8], want[9])
