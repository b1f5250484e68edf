"""Which frontier points are priced at display resolution (``service.octree.builder.spread_points``) and
the one split of point lists by the frame rate (``service.store.split_by_rate``) that it, the search's
warm starts and its comparisons share.

Property tests over random two-tier point lists: at most ``k`` points of each tier, both ends of each
tier, the slow tier spread as the meeting tier is; and a budget-first lookup on a store drawn from the
spread points finds a slow setting near an error budget instead of max quality."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.octree.builder import PROBE_ERROR, kept_up_to_price, spread_points
from service.octree.search import Search
from service.store import (
    Frontier,
    ParetoStore,
    meets_frame_rate,
    pack_indices,
    split_by_rate,
)
from tests.test_store_lookup import PARAMS

FPS = 30.0

#: (settings, error, power, frame time) points; the settings are the point's position, so that equal
#: figures stay distinguishable
point_lists = st.lists(st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 5.0),
                                 st.one_of(st.floats(0.0, 0.2), st.sampled_from([1 / FPS, 0.0]))),
                       max_size=40).map(lambda pts: [((i,), e, p, t) for i, (e, p, t) in enumerate(pts)])


def _ends(tier: list[tuple]) -> set[tuple[float, float]]:
    """A tier's two ends as the spread orders it, by (error, -power): the least error (the most power
    among equal errors) and the most error (the least power among equal ones)."""
    keys = [(pt[1], -pt[2]) for pt in tier]
    return {min(keys), max(keys)}


@settings(max_examples=300, deadline=None)
@given(points=point_lists, fps=st.one_of(st.none(), st.just(FPS), st.floats(1.0, 200.0)))
def test_split_by_rate_parts_the_points_as_the_frame_rate_rule_does(points, fps) -> None:
    meeting, slow = split_by_rate(points, fps)
    meets = [fps is not None and meets_frame_rate(pt[3], fps) for pt in points]
    if not any(meets):  # one tier: all of them, as frontier_tiers has it
        assert meeting == points and slow == []
        return
    assert meeting == [pt for pt, m in zip(points, meets, strict=True) if m]  # order kept
    assert slow == [pt for pt, m in zip(points, meets, strict=True) if not m]
    # the search's warm starts and comparisons read the same meeting tier
    search = Search(SimpleNamespace(fps=fps), None, None, 0)  # type: ignore[arg-type]
    assert search.meeting_tier(points) == meeting


@settings(max_examples=300, deadline=None)
@given(points=point_lists, k=st.integers(0, 10), fps=st.one_of(st.none(), st.just(FPS)))
def test_spread_prices_at_most_k_of_each_tier_with_both_ends(points, k, fps) -> None:
    picked = spread_points(points, k, fps)
    if k == 0:
        assert picked == points
        return
    meeting, slow = split_by_rate(points, fps)
    got_meeting = [pt for pt in picked if pt in meeting]
    got_slow = [pt for pt in picked if pt in slow]
    assert picked == got_meeting + got_slow  # the meeting tier's picks first, each in its list's order
    assert got_meeting == [pt for pt in meeting if pt in picked]
    assert got_slow == [pt for pt in slow if pt in picked]
    # at most k of each tier, exactly k when it holds more: the slow tier's intermediate points are
    # priced as the meeting tier's are (its two ends alone before)
    assert len(got_meeting) == min(k, len(meeting)) and len(got_slow) == min(k, len(slow))
    assert len(picked) <= 2 * k
    for tier, got in ((meeting, got_meeting), (slow, got_slow)):
        if k >= 2 and tier:  # both ends of each tier: the least error and the cheapest
            assert _ends(tier) <= {(pt[1], -pt[2]) for pt in got}


def test_the_slow_tier_is_spread_evenly_by_error() -> None:
    """Nine slow points from error 0.04 down to 0 (max quality) on a straight line, four priced: both
    ends and two between, evenly along it; the meeting tier's three points all priced."""
    meeting = [((0, j), e, p, 0.02) for j, (e, p) in enumerate(((0.3, 0.2), (0.1, 0.4), (0.05, 0.6)))]
    slow = [((1, j), 0.04 - 0.005 * j, 0.7 + 0.05 * j, 0.04 + 0.01 * j) for j in range(9)]
    picked = spread_points(meeting + slow, 4, FPS)
    assert picked[:3] == meeting
    assert [round(pt[1], 3) for pt in picked[3:]] == [0.04, 0.025, 0.015, 0.0]


def test_the_spread_follows_the_curve_not_the_crowd_at_the_cheap_end() -> None:
    """A frontier shaped as chess's on the `desktop` profile: max quality at 26 W, three settings between
    it and error 0.03, then ten cheap settings (error 0.05-0.4) all within a watt of the static power.
    Eight picks evenly by rank put five among the cheap ten and one between max quality and 0.03; along
    the curve the picks cover the steep part, so an error budget of 0.02 finds a setting well below
    max quality's power."""
    knee = [(0.0, 26.0), (0.002, 22.0), (0.01, 19.0), (0.018, 17.5), (0.03, 16.5)]
    cheap = [(0.05 + 0.035 * j, 15.9 - 0.09 * j) for j in range(10)]
    points = [((j,), e, p, 0.02) for j, (e, p) in enumerate(knee + cheap)]
    picked = spread_points(points, 8, FPS)
    assert len(picked) == 8 and picked == [pt for pt in points if pt in picked]
    assert _ends(points) <= {(pt[1], -pt[2]) for pt in picked}
    between = [pt for pt in picked if 0.0 < pt[1] < 0.03]
    assert len(between) >= 2, picked
    within = [pt[2] for pt in picked if pt[1] <= 0.02]
    assert min(within) <= 19.0  # not max quality's 26 W


def test_points_with_equal_figures_are_still_spread_by_rank() -> None:
    points = [((j,), 0.1, 1.0, 0.02) for j in range(9)]
    assert len(spread_points(points, 4, FPS)) == 4


def _setting(n: int) -> tuple[int, int, int]:
    """The ``n``-th of the 24 settings of the test parameters (``PARAMS``: 3 x 2 x 4 values)."""
    return n % 3, (n // 3) % 2, n // 6


def _one_frontier_store(points: list[tuple]) -> ParetoStore:
    """One leaf whose six views share the frontier of ``points`` (drawn as the builder's store is:
    ``Frontier.from_points`` at the store's frame rate)."""
    corners = np.array([[(k & 1), (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], dtype=np.int64)
    fr = Frontier.from_points([pack_indices(pt[0]) for pt in points], [pt[1] for pt in points],
                              [pt[2] for pt in points], [pt[3] for pt in points], fps=FPS)
    return ParetoStore(PARAMS, np.zeros(3), 10.0, 0, np.array([-1]), corners, np.zeros((8, 6), np.int64),
                       [fr], fps=FPS, meta={"static_power_w": 0.1})


def _run_one_frontier_builder(points: list[tuple], pricer, progress=None, should_cancel=None, kept_up=(),
                              near=(), **options):
    """An octree builder whose one measured frontier holds ``points`` (and the search's probes that kept
    up, ``kept_up``, and its slow settings near the deadline, ``near``) and that every view reads, run with
    a stand-in ``pricer`` (its display pricing alone does work), ``progress`` and ``should_cancel``
    callbacks: the builder, after its run."""
    from service.octree.builder import OctreeBuilder, OctreeConfig, PathFrames
    from service.params import default_space

    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])
    cfg = OctreeConfig(threshold_power_w=0.1, threshold_error=0.01, view_sampling="axis", display=(64, 36),
                       **options)
    b = OctreeBuilder(SimpleNamespace(fps=FPS, evaluations=0, cache_hits=0), space,  # type: ignore[arg-type]
                      PathFrames(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])), cfg, progress=progress,
                      pricer=pricer, should_cancel=should_cancel)

    def build() -> None:  # one measured frontier, every view of the root's corners reads it
        b.lattice.add_root()
        b.lattice.set_frontier(0, 0, points, kept_up, near)
        for views in b.lattice.corner_views:
            views[:] = [0] * len(views)

    b.sampling.build = build  # type: ignore[method-assign]
    b.run()
    return b


def table_pricer(figures: dict, asked: list) -> SimpleNamespace:
    """A stand-in display pricer answering each setting with its ``figures`` ((error, power, frame
    time)), recording the settings of each request it is asked for in ``asked``."""
    def price(requests, on_progress=None):
        asked.extend(list(xs) for _, xs in requests)
        return [[SimpleNamespace(error=figures[x][0], power_w=figures[x][1], frame_time_s=figures[x][2])
                 for x in xs] for _, xs in requests]

    return SimpleNamespace(ev=SimpleNamespace(executor=None), price=price)


def test_budget_first_finds_an_intermediate_slow_point_near_the_budget() -> None:
    """Real-time settings reach error 0.05 at best; nine slower ones reach 0.04 down to 0. With the
    spread points priced, an error budget of 0.02 picks the slow setting at 0.015 (0.09 s a frame), not
    max quality (0.12 s), which was the only slow point within it when only the ends were priced."""
    meeting = [(_setting(j), e, p, 0.02) for j, (e, p) in enumerate(((0.3, 0.2), (0.1, 0.4), (0.05, 0.6)))]
    slow = [(_setting(3 + j), 0.04 - 0.005 * j, 0.7 + 0.05 * j, 0.04 + 0.01 * j) for j in range(9)]
    store = _one_frontier_store(spread_points(meeting + slow, 4, FPS))
    fast, slow_tier = store.frontiers[0].tiers(FPS)
    assert slow_tier is not None and len(slow_tier) == 4 and len(fast) == 3
    hit = store.lookup((5.0, 5.0, 5.0), direction=(1.0, 0.0, 0.0), error_budget=0.02, priority="budget")
    assert not hit.infeasible and hit.meets_fps is False
    assert hit.indices == _setting(3 + 5) and round(hit.error, 3) == 0.015
    assert abs(hit.frame_time_s - 0.09) < 1e-6 and abs(hit.fps - 1 / 0.09) < 0.01
    # frame rate first still keeps the frame rate (and misses the budget)
    first = store.lookup((5.0, 5.0, 5.0), direction=(1.0, 0.0, 0.0), error_budget=0.02)
    assert first.infeasible and first.meets_fps and round(first.error, 3) == 0.05


def test_the_builder_prices_the_spread_points_and_draws_the_tiers_from_their_display_figures() -> None:
    """The builder's display pricing with a stand-in pricer: it is asked for the meeting tier and the
    slow tier's spread (not the slow tier's ends alone), the store's tiers are drawn from the figures it
    returns (the cheapest slow point keeps up at display resolution and joins the meeting tier), and a
    budget-first lookup picks the intermediate slow point within the budget."""
    import itertools

    from service.params import default_space

    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])
    settings_ = [space.expand(f) for f in itertools.product(*(range(n) for n in space.free_n_values))][:12]
    meeting = [(settings_[j], e, p, 0.02) for j, (e, p) in enumerate(((0.3, 0.2), (0.1, 0.4), (0.05, 0.6)))]
    slow = [(settings_[3 + j], 0.04 - 0.005 * j, 0.7 + 0.05 * j, 0.04 + 0.01 * j) for j in range(9)]
    display = {pt[0]: (pt[1], pt[2], pt[3]) for pt in meeting + slow}
    display[slow[0][0]] = (0.04, 0.7, 0.03)  # keeps up with 30 fps at display resolution

    class Pricer:
        ev = SimpleNamespace(executor=None)

        def __init__(self) -> None:
            self.asked: list[list[tuple[int, ...]]] = []

        def price(self, requests, on_progress=None):
            self.asked += [list(xs) for _, xs in requests]
            return [[SimpleNamespace(error=display[x][0], power_w=display[x][1], frame_time_s=display[x][2])
                     for x in xs] for _, xs in requests]

    pricer = Pricer()
    b = _run_one_frontier_builder(meeting + slow, pricer, display_points=4)
    want = [pt[0] for pt in meeting] + [slow[j][0] for j in (0, 3, 5, 8)]
    assert pricer.asked == [want] and b.display_points == 7
    store = b.to_store(profile="mobile", fps=FPS, aspect=16 / 9, meta={"static_power_w": 0.1})
    fast, slow_tier = store.frontiers[0].tiers(FPS)
    assert slow_tier is not None
    assert [round(float(e), 3) for e in fast.error] == [0.3, 0.1, 0.05, 0.04]
    assert [round(float(e), 3) for e in slow_tier.error] == [0.025, 0.015, 0.0]
    hit = store.lookup((0.5, 0.0, 0.0), direction=(1.0, 0.0, 0.0), error_budget=0.02, priority="budget")
    assert not hit.infeasible and hit.meets_fps is False and round(hit.error, 3) == 0.015
    assert hit.indices == tuple(slow[5][0])


@settings(max_examples=300, deadline=None)
@given(points=point_lists, k=st.integers(0, 10), k_slow=st.integers(0, 10))
def test_the_slow_tier_gets_its_own_count(points, k, k_slow) -> None:
    """``k_slow`` bounds the slow tier alone (0: all of it) and leaves the meeting tier as ``k`` has it;
    with 1 the slow tier keeps its least-error end, max quality in a frontier, whose figures the
    reference render gives."""
    picked = spread_points(points, k, FPS, k_slow)
    meeting, slow = split_by_rate(points, FPS)
    picked_slow = [pt for pt in picked if pt in slow]
    assert [pt for pt in picked if pt in meeting] == [pt for pt in spread_points(meeting, k) if pt in meeting]
    if not slow:
        assert picked == spread_points(points, k, FPS)
        return
    assert len(picked_slow) == (len(slow) if k_slow == 0 else min(k_slow, len(slow)))
    if k_slow == 1:
        assert [(pt[1], -pt[2]) for pt in picked_slow] == [min((pt[1], -pt[2]) for pt in slow)]
    assert spread_points(points, k, FPS, None) == spread_points(points, k, FPS, k)


def test_the_builder_prices_max_quality_alone_in_the_slow_tier_with_one_slow_point() -> None:
    """``slow_points`` 1: the builder asks the pricer for the meeting tier's spread and the slow tier's
    least-error point only, and a budget-first lookup within a budget no real-time point keeps gets it."""
    import itertools

    from service.params import default_space

    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])
    settings_ = [space.expand(f) for f in itertools.product(*(range(n) for n in space.free_n_values))][:12]
    meeting = [(settings_[j], e, p, 0.02) for j, (e, p) in enumerate(((0.3, 0.2), (0.1, 0.4), (0.05, 0.6)))]
    slow = [(settings_[3 + j], 0.04 - 0.005 * j, 0.7 + 0.05 * j, 0.04 + 0.01 * j) for j in range(9)]
    asked: list[list[tuple[int, ...]]] = []

    class Pricer:
        ev = SimpleNamespace(executor=None)

        def price(self, requests, on_progress=None):
            asked.extend(list(xs) for _, xs in requests)
            return [[SimpleNamespace(error=e, power_w=p, frame_time_s=t)
                     for x in xs for (s, e, p, t) in meeting + slow if s == x] for _, xs in requests]

    b = _run_one_frontier_builder(meeting + slow, Pricer(), display_points=4, slow_points=1)
    assert asked == [[pt[0] for pt in meeting] + [slow[8][0]]] and b.display_points == 4
    store = b.to_store(profile="mobile", fps=FPS, aspect=16 / 9, meta={"static_power_w": 0.1})
    hit = store.lookup((0.5, 0.0, 0.0), direction=(1.0, 0.0, 0.0), error_budget=0.02, priority="budget")
    assert not hit.infeasible and hit.meets_fps is False and hit.error == 0.0
    assert hit.indices == tuple(slow[8][0])


@settings(max_examples=100, deadline=None)
@given(lists=st.lists(point_lists, min_size=1, max_size=6), k=st.integers(0, 6),
       k_slow=st.one_of(st.none(), st.integers(0, 6)),
       changes=st.lists(st.tuples(st.integers(0, 5), st.integers(0, 5), st.booleans()), max_size=8))
def test_the_builders_counted_points_are_the_spread_of_each_frontiers_points(lists, k, k_slow,
                                                                            changes) -> None:
    """The points each frontier keeps to be priced, counted once per points list (the search's progress
    reports read them on every step), are what :func:`spread_points` gives for the points the frontier
    holds now, through frontiers added and points replaced (the guards' worst figures, which may move a
    point to the slow tier) or copied from another frontier; and a report that finds nothing changed
    spreads no frontier again."""
    import service.octree.builder as builder_module
    from service.octree.builder import OctreeBuilder, OctreeConfig, PathFrames
    from service.params import default_space

    cfg = OctreeConfig(threshold_power_w=0.1, threshold_error=0.01, view_sampling="axis", display=(64, 36),
                       display_points=k, slow_points=k_slow)
    b = OctreeBuilder(SimpleNamespace(fps=FPS, evaluations=0, cache_hits=0), default_space(),  # type: ignore[arg-type]
                      PathFrames(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])), cfg,
                      pricer=SimpleNamespace())  # type: ignore[arg-type]
    b.lattice.add_root()
    spreads = 0
    spread = builder_module.spread_points

    def counting(*args, **kw):
        nonlocal spreads
        spreads += 1
        return spread(*args, **kw)

    def check() -> None:
        nonlocal spreads
        recs = b.lattice.frontiers
        want = [len(spread_points(r.points, k, FPS, k_slow)) for r in recs]
        spreads = 0
        assert [b._kept_count(f) for f in range(len(recs))] == want
        again = spreads
        assert [b._kept_count(f) for f in range(len(recs))] == want and spreads == again
        per = sum(want) / len(want)
        views = max(b.state.views_planned, len(recs))
        assert b._pricing_to_come() == (views, pytest.approx(views * per)) and spreads == again

    builder_module.spread_points = counting
    try:
        for n, points in enumerate(lists):
            b.lattice.set_frontier(n % 8, n // 8, points)
            check()
        for target, source, slower in changes:
            recs = b.lattice.frontiers
            rec = recs[target % len(recs)]
            if slower:  # the worst figures over a guard: every point a little slower, a new list
                rec.points = [(x, e, p, t * 1.5 + 0.01) for x, e, p, t in rec.points]
            else:
                rec.points = recs[source % len(recs)].points
            check()
    finally:
        builder_module.spread_points = spread


@settings(max_examples=300, deadline=None)
@given(points=point_lists,
       kept_up=st.lists(st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 5.0)), max_size=8))
def test_the_probes_priced_are_those_more_accurate_than_the_meeting_tier_that_none_dominates(points,
                                                                                           kept_up) -> None:
    """A probe that kept up is priced besides the spread exactly when it is more accurate than every
    real-time point of the frontier and no real-time point or other probe dominates it; none without
    real-time points or a frame-rate target; power ascending, each once."""
    probes = [((100 + i,), e, p, 1 / FPS) for i, (e, p) in enumerate(kept_up)]  # probes keep up
    got = kept_up_to_price(points, probes, FPS)
    assert kept_up_to_price(points, probes, None) == [] and kept_up_to_price(points, [], FPS) == []
    meeting = [pt for pt in points if meets_frame_rate(pt[3], FPS)]
    if not meeting:
        assert got == []
        return
    best = min(pt[1] for pt in meeting)
    pool = [*meeting, *probes]

    def dominated(a) -> bool:
        return any(b is not a and b[1] <= a[1] and b[2] <= a[2] and (b[1], b[2]) != (a[1], a[2])
                   for b in pool)

    want = {pr[0] for pr in probes if pr[1] < best and not dominated(pr)}
    ties = {pr[0] for pr in probes if pr[1] < best and not dominated(pr)
            and any(q is not pr and (q[1], q[2]) == (pr[1], pr[2]) for q in pool)}
    assert want - ties <= {pt[0] for pt in got} <= want  # of equal figures, one is kept
    assert len({pt[0] for pt in got}) == len(got) and all(pt in probes for pt in got)
    assert [pt[2] for pt in got] == sorted(pt[2] for pt in got)


def test_the_builder_prices_a_probe_that_kept_up_where_the_real_time_points_are_far_from_max() -> None:
    """The valley's missed frames at 320x180 without bridging: the search's meeting tier begins at error
    0.04 and its slow tier is a slow max quality; the probe one step below max quality kept up at 0.007
    but was left out of the frontier. With ``slow_points`` 1 (max quality alone there) and no bridging
    the builder now prices it in a second round, since the most accurate real-time point priced is over
    ``PROBE_ERROR`` (0.02), and an error budget of 0.02, frame rate first, is kept at 30 fps with it;
    before, the lookup had nothing real time within the budget. Where the real-time points priced reach
    0.019, the probe is not priced."""
    import itertools

    from service.params import default_space

    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])
    settings_ = [space.expand(f) for f in itertools.product(*(range(n) for n in space.free_n_values))][:12]
    top = space.max_quality_indices()
    slow_max = (top, 0.0, 1.0, 0.045)
    probe = (settings_[5], 0.007, 0.8, 0.03)

    def run(best: float, kept_up):
        meeting = [(settings_[j], e, p, 0.02)
                   for j, (e, p) in enumerate(((0.3, 0.2), (0.1, 0.4), (best, 0.6)))]
        figures = {pt[0]: pt[1:] for pt in (*meeting, slow_max, probe)}
        asked: list[list[tuple[int, ...]]] = []
        b = _run_one_frontier_builder([*meeting, slow_max], table_pricer(figures, asked), kept_up=kept_up,
                                      display_points=4, slow_points=1)
        store = b.to_store(profile="mobile", fps=FPS, aspect=16 / 9, meta={"static_power_w": 0.1})
        hit = store.lookup((0.5, 0.0, 0.0), direction=(1.0, 0.0, 0.0), error_budget=0.02)
        return asked, hit, b, [pt[0] for pt in spread_points([*meeting, slow_max], 4, FPS, 1)]

    asked, hit, b, spread = run(0.04, [probe])
    assert asked == [spread, [probe[0]]] and top in spread and b.probed_points == 1 and b.bridged_points == 0
    assert not hit.infeasible and hit.meets_fps and hit.indices == tuple(probe[0])
    assert round(hit.error, 3) == 0.007
    asked, hit, b, spread = run(0.04, [])  # the frontier alone, as priced before
    assert asked == [spread] and b.probed_points == 0
    assert hit.infeasible and hit.meets_fps and round(hit.error, 3) == 0.04
    assert PROBE_ERROR == 0.02
    asked, hit, b, spread = run(0.019, [probe])  # a real-time point priced within 0.02 already
    assert asked == [spread] and b.probed_points == 0
    assert not hit.infeasible and round(hit.error, 3) == 0.019
