"""The search's probes of the slow region (:meth:`service.octree.search.Search.probes`): settings between
the most accurate real-time one and max quality, evaluated after each search so that the slow tier holds
intermediate points a budget-first lookup can pick, at a small stated cost, and only when a frame-rate
target is missed. A stand-in evaluator with a known error and frame-time model keeps this exact."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from service.evaluation import CameraSpec
from service.nsga import NSGAConfig
from service.octree.builder import kept_up_to_price, spread_points
from service.octree.search import PROBE_CHAIN, Search
from service.params import default_space
from service.store import Frontier, ParetoStore, meets_frame_rate, split_by_rate

FPS = 30.0
SPACE = default_space().subset(["sampling", "max_depth", "resolution_scale"])  # 5 x 4 x 4 settings
CAM = CameraSpec((0.0, -5.0, 1.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), 0.7, 16, 12)


def _gap(indices: tuple[int, ...]) -> float:
    """How far a setting is from max quality: the free parameters' index distances, each over its range."""
    top = SPACE.max_quality_indices()
    return sum(abs(int(top[i]) - int(indices[i])) / (len(SPACE.parameters[i].values) - 1)
               for i in SPACE.free_positions)


class Model:
    """A stand-in evaluator: error grows with the gap to max quality, power falls with it, and only the
    settings within a gap of ~0.47 of max quality (max quality and each parameter one value below it)
    miss 30 fps."""

    def __init__(self, fps: float = FPS) -> None:
        self.fps = fps
        self.evaluations = 0
        self.cache_hits = 0
        self.asked: list[tuple[int, ...]] = []

    def evaluate(self, requests):
        out = []
        for _, x in requests:
            g = _gap(x)
            self.evaluations += 1
            self.asked.append(tuple(x))
            out.append(SimpleNamespace(error=0.05 * g, power_w=1.1 - g / 3,
                                       frame_time_s=0.02 + 0.025 * max(0.0, 1.0 - g)))
        return out


class SamplerModel(Model):
    """The valley's case on `desktop` at 320x180: only the best sampler is slow near max quality, so the
    probe one sampler value below max quality keeps up, more accurate than any real-time setting the
    search itself met."""

    def evaluate(self, requests):
        top = SPACE.max_quality_indices()
        out = []
        for _, x in requests:
            g = _gap(x)
            self.evaluations += 1
            self.asked.append(tuple(x))
            slow = x[0] == top[0] and g < 0.5
            out.append(SimpleNamespace(error=0.05 * g, power_w=1.1 - g / 3,
                                       frame_time_s=0.045 if slow else 0.02))
        return out


def _search(model: Model) -> Search:
    return Search(model, SPACE, NSGAConfig(population=4, generations=2, seed=1), exhaustive_limit=0)  # type: ignore[arg-type]


def _store(points) -> ParetoStore:
    """One leaf whose views all read the frontier of ``points``, drawn as the builder's store is."""
    fr = Frontier.from_points([SPACE.pack(pt[0]) for pt in points], [pt[1] for pt in points],
                              [pt[2] for pt in points], [pt[3] for pt in points], fps=FPS)
    corners = np.array([[(k & 1), (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], dtype=np.int64)
    return ParetoStore(SPACE.to_stored(), np.zeros(3), 10.0, 0, np.array([-1]), corners,
                       np.zeros((8, 6), np.int64), [fr], fps=FPS, meta={"static_power_w": 0.1})


def test_probes_put_intermediate_points_in_the_slow_tier_and_budget_first_picks_one(monkeypatch) -> None:
    """Without probes this search's slow tier is max quality alone (NSGA-II ranks the slow settings
    behind every real-time one and never reaches them); with them it holds the settings one value below
    max quality that miss the rate, and an error budget between them and the best real-time setting is
    kept with one of those, not with max quality. The meeting tier is the search's either way."""
    with monkeypatch.context() as m:
        m.setattr(Search, "probes", lambda self, archive: [])
        plain = _search(Model()).run([CAM], [[]], "search")[0].points
    model = Model()
    search = _search(model)
    probed = search.run([CAM], [[]], "search")[0].points

    def tiers(points):
        return ([pt for pt in points if meets_frame_rate(pt[3], FPS)],
                [pt for pt in points if not meets_frame_rate(pt[3], FPS)])

    fast0, slow0 = tiers(plain)
    fast1, slow1 = tiers(probed)
    assert fast1 == fast0  # probes that keep up are dropped: the meeting tier stays the search's
    assert [pt[0] for pt in slow0] == [SPACE.max_quality_indices()]
    best = min(pt[1] for pt in fast1)
    inner = [pt for pt in slow1 if 0.0 < pt[1] < best]
    assert len(inner) >= 2 and slow1[-1][0] == SPACE.max_quality_indices()
    # the cost: at most the free parameters plus the chain, each evaluated once, counted as one step
    n_probes = len(SPACE.free_positions) + len(PROBE_CHAIN)
    assert 0 < search.probes_evaluated <= n_probes
    assert len(model.asked) == len(set(model.asked))
    assert search.steps_done == search.steps_planned

    store = _store(probed)
    budget = 0.5 * (inner[0][1] + best)  # kept by the cheapest intermediate slow point, by no real-time one
    hit = store.lookup((5.0, 5.0, 5.0), direction=(1.0, 0.0, 0.0), error_budget=budget, priority="budget")
    assert not hit.infeasible and hit.meets_fps is False
    assert hit.indices == inner[0][0] and hit.error == pytest.approx(inner[0][1])
    assert hit.indices != SPACE.max_quality_indices()
    no_probes = _store(plain).lookup((5.0, 5.0, 5.0), direction=(1.0, 0.0, 0.0), error_budget=budget,
                                     priority="budget")
    assert no_probes.indices == SPACE.max_quality_indices()  # what budget first picked before


def test_no_probes_when_every_setting_keeps_up() -> None:
    """At 10 fps every setting keeps up: no slow tier to fill, no probe evaluated."""
    model = Model(fps=10.0)
    search = _search(model)
    points = search.run([CAM], [[]], "search")[0].points
    assert search.probes_evaluated == 0
    assert all(meets_frame_rate(pt[3], 10.0) for pt in points)


def test_probes_are_max_stepped_down_then_a_chain_towards_the_best_real_time_setting() -> None:
    """The probe list itself, from an archive of max quality (slow) and one real-time setting."""
    from service.nsga import Archive

    search = _search(Model())
    top = SPACE.restrict(SPACE.max_quality_indices())  # (4, 3, 3)
    real_time = (0, 1, 3)
    archive = Archive()
    archive.add(top, (0.0, 1.1), False)
    archive.add(real_time, (0.05, 0.3), True)
    got = search.probes(archive)
    singles = [(3, 3, 3), (4, 2, 3), (4, 3, 2)]
    chain = [(3, 3, 3), (2, 2, 3), (1, 1, 3)]  # 1/4, 1/2, 3/4 of the way (rounded half to even)
    assert got == list(dict.fromkeys(singles + chain))
    archive.add((3, 3, 3), (0.01, 1.0), False)
    assert (3, 3, 3) not in search.probes(archive)  # evaluated settings are not probed again
    # a real-time setting as accurate as max quality: nothing to probe
    exact = Archive()
    exact.add(top, (0.0, 1.1), False)
    exact.add((3, 3, 3), (0.0, 0.9), True)
    assert search.probes(exact) == []


def test_probes_that_keep_up_are_returned_beside_the_frontier_for_the_display_pricing() -> None:
    """A probe that keeps up stays out of the search's frontier (its warm starts and comparisons read
    the meeting tier the search found) but is returned beside it, and the display pricing prices it
    besides the frontier's spread, which holds max quality alone of the slow tier with the demo's
    ``slow_points`` 1. Before, it was dropped: the priced meeting tier began at the search's best,
    0.033, with a slow Max above it."""
    model = SamplerModel()
    found = _search(model).run([CAM], [[]], "search")[0]
    top = SPACE.max_quality_indices()
    step = (top[0] - 1, *top[1:])  # the sampler one value below max quality
    assert [pt[0] for pt in found.kept_up] == [step]
    assert all(meets_frame_rate(pt[3], FPS) for pt in found.kept_up)
    assert not {pt[0] for pt in found.kept_up} & {pt[0] for pt in found.points}
    meeting, slow = split_by_rate(found.points, FPS)
    assert found.kept_up[0][1] < min(pt[1] for pt in meeting)  # more accurate than the search's best
    assert slow and slow[-1][0] == top
    assert model.asked.count(step) == 1 and found.kept_up[0][1:] == (0.05 * 0.25, 1.1 - 0.25 / 3, 0.02)

    extra = kept_up_to_price(found.points, found.kept_up, FPS)
    assert [pt[0] for pt in extra] == [step]  # priced besides the spread, which never holds it
    spread = [pt[0] for pt in spread_points(found.points, 4, FPS, 1)]
    assert step not in spread and top in spread


# -- the descent from max quality -------------------------------------------------------------------------
LAB_SPACE = default_space().subset(["sampling", "shadow_samples", "resolution_scale", "ao_samples"])


class LabModel(Model):
    """The lab's heavy cameras at the search's small images: the sampler and the resolution set the
    error, shadow rays and AO samples set most of the frame time and add little error. Max takes three
    frame deadlines; FSAA at full resolution keeps up only with few shadow rays and little AO."""

    def evaluate(self, requests):
        out = []
        for _, x in requests:
            s, h, r, a = (int(x[i]) for i in LAB_SPACE.free_positions)
            self.evaluations += 1
            self.asked.append(tuple(x))
            error = 0.04 * (4 - s) + 0.03 * (3 - r) + 0.002 * (3 - h) + 0.001 * (3 - a)
            deadlines = (0.3 + 0.25 * s / 4 + 0.2 * r / 3) * (1 + 2.0 * h / 3 + 1.0 * a / 3)
            out.append(SimpleNamespace(error=error, power_w=1.0 + deadlines, frame_time_s=deadlines / FPS))
        return out


def _lab_search(model: LabModel, descent_steps: int) -> Search:
    return Search(model, LAB_SPACE, NSGAConfig(population=4, generations=2, seed=3),  # type: ignore[arg-type]
                  exhaustive_limit=0, descent_steps=descent_steps)


def test_the_descent_from_max_reaches_the_accurate_real_time_setting_the_search_missed() -> None:
    """Stepping down from a slow Max, each step the one that saves the most frame time for the error it
    adds, keeps the sampler and the resolution and gives up shadow rays and AO until it keeps up: a
    real-time setting far more accurate than any the short NSGA-II search met. Without the option no
    descent runs and the search is what it was."""
    plain_model = LabModel()
    plain = _lab_search(plain_model, 0)
    found0 = plain.run([CAM], [[]], "search")[0]
    assert plain.descent_evaluated == 0
    real_time0 = [pt for pt in [*found0.points, *found0.kept_up] if meets_frame_rate(pt[3], FPS)]
    assert min(pt[1] for pt in real_time0) > 0.02

    model = LabModel()
    search = _lab_search(model, 8)
    found = search.run([CAM], [[]], "search")[0]
    assert model.asked[:len(plain_model.asked)] == plain_model.asked  # the search itself unchanged
    assert 0 < search.descent_evaluated <= 8 * len(LAB_SPACE.free_positions)
    assert search.steps_done == search.steps_planned
    top = LAB_SPACE.max_quality_indices()
    sampler, _, resolution, _ = LAB_SPACE.free_positions
    best = min(found.kept_up, key=lambda pt: pt[1])
    assert best[1] <= 0.01 and meets_frame_rate(best[3], FPS)
    assert best[0][sampler] == top[sampler] and best[0][resolution] == top[resolution]
    # the slow settings it passed join the slow tier, between Max and the real-time points
    slow = [pt for pt in found.points if not meets_frame_rate(pt[3], FPS)]
    assert any(pt[0][sampler] == top[sampler] and pt[0][resolution] == top[resolution] and pt[0] != top
               for pt in slow)
    # each step evaluated the settings one parameter one value below where it stood
    descent = model.asked[len(plain_model.asked):]

    def apart(x, y):
        return sum(abs(int(u) - int(v)) for u, v in zip(x, y, strict=True))
    assert descent and all(any(apart(x, y) == 1 for y in [top, *descent]) for x in descent)


def test_a_descent_step_takes_the_most_frame_time_for_the_error_it_adds() -> None:
    at = (0.010, 3.0)
    # 0.5 / 0.002 beats 2.0 / 0.041 and 0.1 / 0.001
    assert Search.best_step(at, [(0.011, 2.5), (0.050, 1.0), (0.010, 2.9)]) == 0
    assert Search.best_step(at, [(0.0, 3.0), (0.02, 3.5)]) is None  # nothing saves time
    assert Search.best_step(at, [(0.005, 2.0), (0.012, 1.0)]) == 0  # less error counts as none added
