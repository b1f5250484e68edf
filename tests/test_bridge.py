"""Settings priced between a frontier's priced points where their errors jump (service.octree.bridge)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.octree.bridge import (
    ERROR_FLOOR,
    GAP_RATIO,
    NEAR_DEADLINES,
    bridge_candidates,
    descents,
    gaps,
    nudges,
)
from service.octree.search import FRACTION_BEFORE_DONE
from tests.test_spread_points import FPS, _run_one_frontier_builder

indices = st.tuples(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3))
priced_points = st.lists(st.tuples(indices, st.floats(0.0, 0.5), st.floats(0.0, 5.0),
                                   st.sampled_from([0.01, 0.02, 0.1])), max_size=12,
                         unique_by=lambda pt: pt[0])


@settings(max_examples=300, deadline=None)
@given(points=priced_points, k=st.integers(0, 10))
def test_bridges_are_a_gaps_cheaper_end_with_one_parameter_of_its_dearer_end(points, k) -> None:
    """At most ``k`` settings, none priced already, none twice; each is the cheaper end of a gap of the
    priced real-time points with exactly one parameter set to the dearer end's value, a descent's
    slow start with one parameter one value nearer the meeting top's, or a nudge's slow start with one
    parameter one value cheaper; no gap, no descent and no nudge, no bridge."""
    priced = [pt[0] for pt in points]
    got = bridge_candidates(points, FPS, k, priced)
    found = gaps(points, FPS)
    down = descents(points, FPS)
    nudged = nudges(points, FPS)
    for _, start, top in nudged:
        assert 1.0 / FPS < start[3] <= NEAR_DEADLINES / FPS and top[3] <= 1.0 / FPS and start[1] < top[1]
    assert len(got) <= max(k, 0) and len(set(got)) == len(got) and not set(got) & set(priced)
    for ratio, cheap, dear in found:
        assert ratio > GAP_RATIO and cheap[2] <= dear[2] and cheap[1] > dear[1]
    for ratio, start, top in down:
        assert ratio > GAP_RATIO and start[3] > 1.0 / FPS >= top[3] and start[1] < top[1]
    for x in got:
        assert any(sum(a != b for a, b in zip(x, cheap[0], strict=True)) == 1
                   and all(a in (b, c) for a, b, c in zip(x, cheap[0], dear[0], strict=True))
                   for _, cheap, dear in found) or any(
            sum(abs(a - b) for a, b in zip(x, start[0], strict=True)) == 1
            and sum(abs(a - c) for a, c in zip(x, top[0], strict=True))
            == sum(abs(b - c) for b, c in zip(start[0], top[0], strict=True)) - 1
            for _, start, top in down) or any(
            [b - a for a, b in zip(x, start[0], strict=True) if a != b] == [1] for _, start, _ in nudged)
    if not found and not down and not nudged:
        assert got == []


def test_a_slow_max_far_more_accurate_than_the_real_time_points_is_stepped_down_toward_them() -> None:
    """The lab on `desktop`: Max (error 0) misses 30 fps, the most accurate real-time point has error
    0.05. The bridges step Max one value toward that point in each parameter they differ in (none
    between two real-time points exists here); the next round starts from the fastest slow point still
    far more accurate (a step that still misses the rate), not from Max again. (Both slow points miss
    the rate by more than NEAR_DEADLINES: no nudges.)"""
    slow_max = ((3, 3, 3), 0.0, 38.0, 0.045)
    cheap = ((1, 3, 0), 0.05, 20.0, 0.02)
    assert gaps([cheap, slow_max], FPS) == []
    assert bridge_candidates([cheap, slow_max], FPS, 8, [cheap[0], slow_max[0]]) == [(2, 3, 3), (3, 3, 2)]
    step = ((2, 3, 3), 0.004, 37.0, 0.044)  # nearer, still slow
    (ratio, start, top), = descents([cheap, slow_max, step], FPS)
    assert start == step and top == cheap and ratio == (0.05 + ERROR_FLOOR) / (0.004 + ERROR_FLOOR)
    assert bridge_candidates([cheap, slow_max, step], FPS, 8, [cheap[0], slow_max[0], step[0], (3, 3, 2)]) \
        == [(1, 3, 3), (2, 3, 2)]
    # a real-time point as accurate as the slow tier (ratio under 2): nothing to descend to
    assert descents([((2, 3, 3), 0.0005, 30.0, 0.03), slow_max], FPS) == []
    # no frame rate, or nothing keeps up: one tier, no descent
    assert descents([cheap, slow_max], None) == [] and descents([slow_max], FPS) == []


def test_a_slow_point_that_nearly_keeps_up_is_stepped_down_in_each_parameter() -> None:
    """The valley at 640x360: the most accurate real-time point has error 0.022 (4 shadow rays, no AO);
    a slow point at 0.016 misses 30 fps by a tenth (27.5 fps). Stepping it toward the real-time point
    (a descent) would need a ratio over 2 and would only bring back its shadow rays; a nudge prices it
    one value cheaper in each parameter, where a step may keep the rate at an error under 0.022."""
    top = ((3, 2, 0), 0.022, 30.0, 0.026)
    near = ((2, 1, 3), 0.016, 33.0, 1.0 / 27.5)
    far_slow = ((3, 3, 3), 0.0, 42.0, 0.14)  # Max at 7 fps: a descent's start, not a nudge's
    assert gaps([top, near], FPS) == [] and descents([top, near], FPS) == []
    (ratio, start, got_top), = nudges([top, near, far_slow], FPS)
    assert start == near and got_top == top and ratio == (0.022 + ERROR_FLOOR) / (0.016 + ERROR_FLOOR)
    assert bridge_candidates([top, near], FPS, 8, [top[0], near[0]]) == [(1, 1, 3), (2, 0, 3), (2, 1, 2)]
    # no nudge from a slow point less accurate than the top, nor from one slower than NEAR_DEADLINES
    assert nudges([top, ((2, 1, 3), 0.03, 33.0, 1.0 / 27.5)], FPS) == []
    assert nudges([top, ((2, 1, 3), 0.016, 33.0, 1.01 * NEAR_DEADLINES / FPS)], FPS) == []
    assert nudges([top, near], None) == [] and nudges([near], FPS) == []
    # beside a gap, and a descent (a slow Max within 1.25 deadlines), nudges take only what they leave of k
    cheapest = ((0, 0, 0), 0.3, 10.0, 0.02)
    three = [cheapest, top, near]
    assert bridge_candidates(three, FPS, 2, [pt[0] for pt in three]) == [(3, 0, 0), (0, 2, 0)]
    assert bridge_candidates(three, FPS, 4, [pt[0] for pt in three]) \
        == [(3, 0, 0), (0, 2, 0), (1, 1, 3), (2, 0, 3)]
    slow_max, cheap = ((3, 3, 3), 0.0, 38.0, 0.036), ((1, 3, 0), 0.05, 20.0, 0.02)
    assert bridge_candidates([cheap, slow_max], FPS, 2, [cheap[0], slow_max[0]]) == [(2, 3, 3), (3, 3, 2)]
    assert bridge_candidates([cheap, slow_max], FPS, 8, [cheap[0], slow_max[0]]) \
        == [(2, 3, 3), (3, 3, 2), (3, 2, 3)]


def test_a_gap_is_measured_with_the_error_floor_so_jumps_near_max_count() -> None:
    """Errors 0.004 and 0 (ratio 5 with the floor) are a gap; 0.0004 and 0 (1.4) are not, nor are
    0.3 and 0.16 (under 2); settings that miss the frame rate are not bridged."""
    def pts(*errors, t=0.01):
        return [((j, 0, 0), e, float(j + 1), t) for j, e in enumerate(errors)]  # power ascending

    assert [round(r, 2) for r, _, _ in gaps(pts(0.004, 0.0), FPS)] == [(0.004 + ERROR_FLOOR) / ERROR_FLOOR]
    assert gaps(pts(0.0004, 0.0), FPS) == [] and gaps(pts(0.3, 0.16), FPS) == []
    slow = pts(0.1, 0.0)
    slow[1] = (slow[1][0], 0.0, slow[1][2], 0.2)  # the dearer one misses 30 fps: the tiers differ
    assert gaps(slow, FPS) == []


def test_the_widest_gap_gets_the_first_bridges_in_turns() -> None:
    """Two gaps: the one near Max (0.04 to 0, ratio 41) is asked first, then they take turns."""
    cheap, mid, best = ((0, 0, 0), 0.28, 1.0, 0.01), ((1, 2, 0), 0.04, 2.0, 0.01), ((3, 3, 3), 0.0, 3.0, 0.01)
    got = bridge_candidates([cheap, mid, best], FPS, 4, [cheap[0], mid[0], best[0]])
    assert got == [(3, 2, 0), (1, 0, 0), (1, 3, 0), (0, 2, 0)]


def _figures(x):
    """A scene's display figures for the space (sampling, max_depth, resolution_scale): each step below
    Max costs error and saves power; Max is (4, 3, 3), error 0 at 30 W."""
    s, d, r = x
    return 0.01 * (4 - s) + 0.03 * (3 - d) + 0.05 * (3 - r), 15.0 + 1.5 * s + 2.0 * d + 1.0 * r


def test_the_builder_prices_a_bridge_and_the_error_budget_picks_it_over_max() -> None:
    """The search kept the cheapest setting, one at (3, 2, 3) that looked good at its small images but
    measures 0.04 at display resolution, and Max: an error budget of 0.02 could only pick Max (30 W).
    With bridging the builder also prices (3, 2, 3) with Max's depth, (3, 3, 3): 0.01 at 28.5 W, which
    the budget then picks; nothing is priced twice, and at most ``bridge_points`` more a frontier."""
    from service.params import default_space

    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])  # the helper's space
    searched = [(space.expand(x), e, p, 0.02)
                for x, e, p in (((0, 0, 0), 0.2, 15.0), ((3, 2, 3), 0.005, 26.5), ((4, 3, 3), 0.0, 30.0))]
    asked: list[tuple[int, ...]] = []

    class Pricer:
        ev = SimpleNamespace(executor=None)

        def price(self, requests, on_progress=None):
            out = []
            for _, xs in requests:
                asked.extend(space.restrict(x) for x in xs)
                out.append([SimpleNamespace(error=e, power_w=p, frame_time_s=0.02)
                            for e, p in (_figures(space.restrict(x)) for x in xs)])
            return out

    reports = []

    def pick(**options):
        asked.clear()
        reports.clear()
        b = _run_one_frontier_builder(searched, Pricer(), reports.append, display_points=8, **options)
        store = b.to_store(profile="mobile", fps=FPS, aspect=16 / 9, meta={"static_power_w": 15.0})
        hit = store.lookup((0.5, 0.0, 0.0), direction=(1.0, 0.0, 0.0), error_budget=0.02)
        return b, hit

    b, hit = pick()
    assert space.restrict(hit.indices) == (4, 3, 3) and b.bridged_points == 0 and len(asked) == 3
    b, hit = pick(bridge_points=4)
    assert space.restrict(hit.indices) == (3, 3, 3)
    assert round(hit.error, 6) == 0.01 and round(hit.power_w, 6) == 28.5
    assert len(asked) == len(set(asked)) == 3 + b.bridged_points and 0 < b.bridged_points <= 4
    assert b.display_points == len(asked)
    # the fraction done held the bridging's most in reserve: it rose through the rounds, never stalled
    fractions = [r.fraction for r in reports]
    bridging = [r.fraction for r in reports if r.phase == "price between the priced points"]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert bridging and bridging[0] < min(bridging[-1], FRACTION_BEFORE_DONE)


def _clocked_bridging(monkeypatch, *, search_evaluations: int, first_round_cached: bool,
                      cameras: int = 1, cached_bridging_batches: int = 0, knows_cache: bool = False):
    """A one-frontier build with bridging on a stand-in clock: each setting the pricer renders takes 1 s;
    with ``first_round_cached`` the first pricing round is answered from the evaluation cache (no time,
    nothing rendered), and so are the bridging's first ``cached_bridging_batches`` batches.
    ``search_evaluations``: what the search rendered of its own; ``cameras``: the frontier's pricing
    cameras (copies of its one); ``knows_cache``: the pricer says before each round how many settings it
    will render (as DisplayPricer.uncached does from the evaluation cache). Returns the builder, its
    progress reports and the seconds each phase's pricing took."""
    import time as time_module

    import service.octree.builder as builder_module
    from service.octree.view_cubes import ViewCubeSampling
    from service.params import default_space

    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])
    searched = [(space.expand(x), e, p, 0.02)
                for x, e, p in (((0, 0, 0), 0.2, 15.0), ((3, 2, 3), 0.005, 26.5), ((4, 3, 3), 0.0, 30.0))]
    clock = [1000.0]
    priced_at: dict[str, float] = {}  # phase -> seconds its pricing took (the stand-in clock's)
    phase = [""]

    class Pricer:
        ev = SimpleNamespace(executor=None)
        evaluations = 0

        bridging_batches = 0
        rounds = 0

        def count(self, requests):
            # what price() will render of this round's requests (batches of 8 cameras, the builder's)
            self.rounds += 1
            n = sum(len(xs) for _, xs in requests)
            if self.rounds == 1:
                return 0 if first_round_cached else n
            return n - sum(len(xs) for _, xs in requests[:8 * cached_bridging_batches])

        def price(self, requests, on_progress=None):
            n = sum(len(xs) for _, xs in requests)
            bridging = phase[0] == "price between the priced points"
            self.bridging_batches += bridging
            if not ((first_round_cached and not bridging)
                    or (bridging and self.bridging_batches <= cached_bridging_batches)):
                clock[0] += n
                priced_at[phase[0]] = priced_at.get(phase[0], 0.0) + n
                self.evaluations += n
            return [[SimpleNamespace(error=e, power_w=p, frame_time_s=0.02)
                     for e, p in (_figures(space.restrict(x)) for x in xs)] for _, xs in requests]

    reports = []

    def progress(r) -> None:
        phase[0] = r.phase
        reports.append(r)

    monkeypatch.setattr(time_module, "perf_counter", lambda: clock[0])
    real_init = builder_module.OctreeBuilder.__init__

    def init(self, evaluator, *args, **kwargs):
        real_init(self, SimpleNamespace(fps=FPS, evaluations=search_evaluations, cache_hits=0), *args,
                  **kwargs)

    monkeypatch.setattr(builder_module.OctreeBuilder, "__init__", init)
    one_camera = ViewCubeSampling.pricing_cameras
    monkeypatch.setattr(ViewCubeSampling, "pricing_cameras",
                        lambda self: {fid: cams * cameras for fid, cams in one_camera(self).items()})
    pricer = Pricer()
    if knows_cache:
        pricer.uncached = pricer.count
    b = _run_one_frontier_builder(searched, pricer, progress, display_points=8, bridge_points=4)
    assert b.bridged_points > 0
    return b, reports, priced_at


def test_a_bridging_rounds_time_left_goes_by_the_pricing_before_it(monkeypatch) -> None:
    """The time left a bridging round first reports is the rounds before it's pace, times what it prices:
    the search's pace counts the display pricing's time over the search's own renders, and over a search
    answered from the evaluation cache (one render here) gave days for minutes."""
    _, reports, priced_at = _clocked_bridging(monkeypatch, search_evaluations=1, first_round_cached=False)
    first = next(r for r in reports if r.phase == "price between the priced points")
    took = priced_at["price between the priced points"]
    assert first.estimate_s is not None and took / 2 <= first.estimate_s <= 2 * took


def test_the_first_pricing_rounds_time_left_includes_the_bridging_after_it(monkeypatch) -> None:
    """The first pricing round is not the job's last phase when bridging follows it: its time left at its
    last batch is the bridging still to come (the most it may price, at the round's own pace), not 0 s
    (the hall's first round at 640x360 read 87 s left with an hour of bridging after it); only the
    last round's last batch reads 0 s. The bound holds: what the bridging took is within it."""
    _, reports, priced_at = _clocked_bridging(monkeypatch, search_evaluations=1, first_round_cached=False)
    first = [r for r in reports if r.phase == "price at display resolution"]
    bridging = [r for r in reports if r.phase == "price between the priced points"]
    took = priced_at["price between the priced points"]
    assert took > 0 and first and bridging
    assert first[-1].estimate_s is not None and first[-1].estimate_s >= took
    assert first[-1].estimate_s == pytest.approx(4 * 1.0)  # 4 bridge points at the round's 1 s a setting
    assert bridging[-1].estimate_s == 0.0


def test_a_bridging_round_after_a_cached_round_does_not_promise_no_time_left(monkeypatch) -> None:
    """A rerun from a copied data folder answers the first pricing round from the evaluation cache in no
    time; the bridging round after it renders. Its first time left is not that cached round's pace (which
    said ~0 s for an hour's work at 1280x720) but unknown, or the search's guess."""
    _, reports, priced_at = _clocked_bridging(monkeypatch, search_evaluations=0, first_round_cached=True)
    first = next(r for r in reports if r.phase == "price between the priced points")
    took = priced_at["price between the priced points"]
    assert took > 0 and (first.estimate_s is None or first.estimate_s >= took / 2)


def test_cached_pricing_batches_do_not_promise_no_time_left(monkeypatch) -> None:
    """A rerun from a copied data folder with more bridge points: the bridging's first batch of cameras
    is answered from the evaluation cache in no time, the batches after it render. The time left after
    that cached batch is not ~0 s (it read 0.0 for the whole batch run of a 640x360 rerun) but unknown,
    a guess, or about the work still to come; once a batch renders, the pace is the renders' own."""
    _, reports, priced_at = _clocked_bridging(monkeypatch, search_evaluations=0, first_round_cached=True,
                                              cameras=20, cached_bridging_batches=1)
    bridging = [r for r in reports if r.phase == "price between the priced points"]
    took = priced_at["price between the priced points"]
    assert took > 0 and len(bridging) >= 3
    after_cached = bridging[1]  # the report after the first (cached) batch of 8 of the 20 cameras
    assert after_cached.estimate_s is None or after_cached.estimate_s >= took / 2
    after_rendered = bridging[2]  # after the second batch, which rendered: its own pace, 4 cameras left
    assert after_rendered.estimate_s is not None and 0 < after_rendered.estimate_s <= took


def test_a_pricer_that_knows_its_cache_gives_the_exact_renders_left(monkeypatch) -> None:
    """The same rerun, with the pricer counting the settings its cache does not hold before each round:
    after the second batch (8 cameras rendered, 4 left) the time left is their pace times exactly the
    4 cameras' renders, where the share of the round's requests rendered so far (the cached first batch
    counted in) made it half that."""
    _, reports, priced_at = _clocked_bridging(monkeypatch, search_evaluations=0, first_round_cached=True,
                                              cameras=20, cached_bridging_batches=1, knows_cache=True)
    bridging = [r for r in reports if r.phase == "price between the priced points"]
    took = priced_at["price between the priced points"]  # 12 cameras rendered, 1 s a setting
    after_rendered = bridging[2]
    assert after_rendered.estimate_s == pytest.approx(took * 4 / 12)
    assert bridging[-1].estimate_s == 0.0


def test_a_cancel_stops_a_pricing_batch_between_its_cameras(monkeypatch) -> None:
    """A cancel requested while a batch of cameras is priced at display resolution stops the batch at its
    next camera, not once the batch is done (a batch of the village at 640x360 took over ten minutes);
    until then each camera priced moves the fraction done."""
    import pytest

    from service.octree.search import Cancelled
    from service.octree.view_cubes import ViewCubeSampling
    from service.params import default_space

    space = default_space().subset(["sampling", "max_depth", "resolution_scale"])
    searched = [(space.expand(x), e, p, 0.02)
                for x, e, p in (((0, 0, 0), 0.2, 15.0), ((3, 2, 3), 0.005, 26.5), ((4, 3, 3), 0.0, 30.0))]
    priced = []  # cameras priced

    class Pricer:
        ev = SimpleNamespace(executor=None)
        evaluations = 0

        def price(self, requests, on_progress=None):
            out = []
            n = sum(len(xs) for _, xs in requests)
            for _, xs in requests:
                out.append([SimpleNamespace(error=e, power_w=p, frame_time_s=0.02)
                            for e, p in (_figures(space.restrict(x)) for x in xs)])
                priced.append(len(xs))
                if on_progress is not None:
                    on_progress(sum(len(x) for _, x in requests[:len(out)]), n)
            self.evaluations += n
            return out

    one_camera = ViewCubeSampling.pricing_cameras
    monkeypatch.setattr(ViewCubeSampling, "pricing_cameras",
                        lambda self: {fid: cams * 20 for fid, cams in one_camera(self).items()})
    reports = []
    with pytest.raises(Cancelled):
        _run_one_frontier_builder(searched, Pricer(), reports.append, should_cancel=lambda: len(priced) >= 3,
                                  display_points=8)
    assert len(priced) == 3  # of a batch of 8 cameras
    assert reports[-1].phase == "cancelled"
    pricing = [r.fraction for r in reports if r.phase == "price at display resolution"]
    assert pricing == sorted(pricing) and len(set(pricing)) == 3  # the start, then the 2 cameras before


def test_a_pricing_round_answered_from_the_cache_ends_with_nothing_left(monkeypatch) -> None:
    """A rerun from a copied data folder: the first pricing round is answered from the evaluation cache,
    nothing rendered, so it has no pace. Once its last camera is done its time left is the bridging's
    after it alone (by the search's guess: 4 bridge points at each of the 20 cameras), not unknown or
    the round's first guess, which counted the round itself; the last round ends with nothing left."""
    import service.octree.builder as builder_module

    def guess(self, state, cameras, points):  # the search's guess: 1 s a reference or setting
        return float(cameras + points)

    monkeypatch.setattr(builder_module.OctreeBuilder, "pricing_time", guess)
    _, reports, _ = _clocked_bridging(monkeypatch, search_evaluations=1, first_round_cached=True, cameras=20)
    pricing = [r for r in reports if r.phase == "price at display resolution"]
    assert len(pricing) >= 3 and pricing[-1].estimate_s == pytest.approx(20 * 4)
    assert pricing[0].estimate_s > pricing[-1].estimate_s
    assert [r for r in reports if r.phase == "price between the priced points"][-1].estimate_s == 0.0
