"""NSGA-II core: sorting and crowding against brute force, hypervolume, determinism, archive, search."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from service import nsga

# objective values from a small grid so ties and duplicates are common
points = st.lists(st.tuples(st.integers(0, 5), st.integers(0, 5)), min_size=1, max_size=25)


def _brute_dominates(a, b) -> bool:
    return all(x <= y for x, y in zip(a, b, strict=True)) and any(x < y for x, y in zip(a, b, strict=True))


def _brute_ranks(P) -> list[int]:
    rank = [-1] * len(P)
    left = set(range(len(P)))
    r = 0
    while left:
        front = {i for i in left if not any(_brute_dominates(P[j], P[i]) for j in left if j != i)}
        for i in front:
            rank[i] = r
        left -= front
        r += 1
    return rank


def _brute_crowding(P) -> list[float]:
    n = len(P)
    if n <= 2:
        return [float("inf")] * n
    d = [0.0] * n
    for m in range(len(P[0])):
        order = sorted(range(n), key=lambda i: (P[i][m], i))
        lo, hi = P[order[0]][m], P[order[-1]][m]
        d[order[0]] = d[order[-1]] = float("inf")
        for k in range(1, n - 1):
            if hi > lo:
                d[order[k]] += (P[order[k + 1]][m] - P[order[k - 1]][m]) / (hi - lo)
    return d


@given(points)
def test_sorting_matches_brute_force(P) -> None:
    F = np.asarray(P, dtype=float)
    assert nsga.rank_of(F).tolist() == _brute_ranks(P)
    mask = nsga.non_dominated_mask(F)
    assert mask.tolist() == [r == 0 for r in _brute_ranks(P)]
    # 3 objectives go through the general path
    F3 = np.column_stack([F, F[:, 0] - F[:, 1]])
    assert nsga.non_dominated_mask(F3).tolist() == [r == 0 for r in _brute_ranks(F3.tolist())]


@given(points)
def test_crowding_matches_brute_force(P) -> None:
    got = nsga.crowding_distance(np.asarray(P, dtype=float))
    want = _brute_crowding(P)
    assert np.allclose(got, want)


def test_crowding_known_values() -> None:
    F = np.array([[0.0, 4.0], [1.0, 2.0], [2.0, 1.0], [4.0, 0.0]])
    # inner points: (2-0)/4 + (4-1)/4 = 1.25 and (4-1)/4 + (2-0)/4 = 1.25
    assert nsga.crowding_distance(F).tolist() == [np.inf, 1.25, 1.25, np.inf]


@given(points)
def test_hypervolume_matches_grid_count(P) -> None:
    F = np.asarray(P, dtype=float)
    ref = (6.0, 6.0)
    # unit cells [x, x+1) x [y, y+1) dominated by some point
    cells = sum(1 for x in range(6) for y in range(6) if any(a <= x and b <= y for a, b in P))
    assert nsga.hypervolume_2d(F, ref) == pytest.approx(cells)


def _problem(n_params: int = 6, n_vals: int = 4, seed: int = 1):
    rng = np.random.default_rng(seed)
    W = rng.random((n_params, n_vals))
    V = rng.random((n_params, n_vals))
    idx = np.arange(n_params)

    def f(batch):
        X = np.asarray(batch)
        e = (W[idx, X] ** 2).sum(1)
        p = V[idx, X].sum(1) + 0.3 * np.sin(3 * e)
        return np.stack([e, p], 1)

    return f, [n_vals] * n_params


def test_same_seed_same_frontier_and_archive() -> None:
    f, nv = _problem()
    runs = [nsga.optimise(f, nv, nsga.NSGAConfig(population=12, generations=8, seed=s), exhaustive_limit=0)
            for s in (5, 5, 6)]
    assert list(runs[0].points.items()) == list(runs[1].points.items())
    assert runs[0].frontier() == runs[1].frontier()
    assert list(runs[0].points) != list(runs[2].points)


def test_never_asks_twice_and_archive_frontier() -> None:
    f, nv = _problem(3, 3)
    algo = nsga.NSGA2(nv, nsga.NSGAConfig(population=6, generations=100, seed=0))
    asked = []
    while not algo.done:
        b = algo.ask()
        asked += b
        algo.tell(f(b))
    assert len(asked) == len(set(asked)) == 27  # the whole space, each setting once
    xs, F = algo.archive.arrays()
    exact = {tuple(x) for x, m in zip(xs, nsga.non_dominated_mask(F), strict=True) if m}
    assert {x for x, _, _ in algo.archive.frontier()} == exact


def test_warm_start_is_the_first_population() -> None:
    _f, nv = _problem()
    init = [(0, 1, 2, 3, 0, 1), (3, 3, 3, 3, 3, 3)]
    algo = nsga.NSGA2(nv, nsga.NSGAConfig(population=8, seed=0), initial=init)
    assert algo.ask()[:2] == init
    with pytest.raises(ValueError):
        nsga.NSGA2(nv, initial=[(9, 0, 0, 0, 0, 0)])


def test_exhaustive_is_exact_and_nsga_is_close() -> None:
    f, nv = _problem(7, 4)  # 16,384 settings
    xs = nsga.enumerate_space(nv)
    F = f(xs)
    lo, hi = F.min(0), F.max(0)
    exact = F[nsga.non_dominated_mask(F)]
    hv_exact = nsga.hypervolume_2d((exact - lo) / (hi - lo), (1, 1))
    arch = nsga.optimise(f, nv, nsga.NSGAConfig(seed=0), exhaustive_limit=0)
    assert len(arch) <= 600
    fr = np.array([[e, p] for _, e, p in arch.frontier()])
    assert nsga.hypervolume_2d((fr - lo) / (hi - lo), (1, 1)) >= 0.98 * hv_exact
    f4, nv4 = _problem(4, 4)
    small = nsga.optimise(f4, nv4, exhaustive_limit=512)
    assert len(small) == 256
    xs4 = nsga.enumerate_space(nv4)
    F4 = f4(xs4)
    want = {x for x, m in zip(xs4, nsga.non_dominated_mask(F4), strict=True) if m}
    assert {x for x, _, _ in small.frontier()} <= want
    assert {(round(e, 12), round(p, 12)) for _, e, p in small.frontier()} == {
        (round(a, 12), round(b, 12)) for a, b in F4[nsga.non_dominated_mask(F4)]}


def test_ask_tell_misuse() -> None:
    algo = nsga.NSGA2([3, 3])
    with pytest.raises(RuntimeError):
        algo.tell([[0, 0]])
    b = algo.ask()
    with pytest.raises(RuntimeError):
        algo.ask()
    with pytest.raises(ValueError):
        algo.tell(np.zeros((len(b) + 1, 2)))
    with pytest.raises(ValueError):
        algo.tell(np.full((len(b), 2), np.nan))


@given(points, st.data())
def test_constrained_fronts_put_feasible_points_first(P, data) -> None:
    F = np.asarray(P, dtype=float)
    feasible = np.asarray(data.draw(st.lists(st.booleans(), min_size=len(P), max_size=len(P))))
    fronts = nsga.constrained_fronts(F, feasible)
    assert sorted(np.concatenate(fronts).tolist()) == list(range(len(P)))
    seen_infeasible = False
    for front in fronts:  # every feasible front before every infeasible one, never mixed
        kinds = set(feasible[front].tolist())
        assert len(kinds) == 1
        seen_infeasible |= not kinds.pop()
        assert not (seen_infeasible and feasible[front].any())
    for ok in (True, False):  # within each group, the group's own non-dominated sort
        group = np.flatnonzero(feasible == ok)
        if group.size:
            ranks = _brute_ranks([P[i] for i in group])
            offset = 0 if ok else sum(1 for f in fronts if feasible[f].all())
            got = nsga.rank_of(F, feasible)[group] - offset
            assert got.tolist() == ranks
    assert [f.tolist() for f in nsga.constrained_fronts(F)] == [
        f.tolist() for f in nsga.non_dominated_sort(F)]


def test_archive_frontier_and_search_keep_to_feasible_points() -> None:
    """Infeasible points (here: the cheap, slow corner of the space) never reach the frontier while a
    feasible point exists; with none feasible the frontier is that of all points."""
    f, nv = _problem(4, 4)

    def slow(batch):  # "misses the frame rate": half the space, cheap points included
        F = f(batch)
        return F[:, 1] < np.median(f(nsga.enumerate_space(nv))[:, 1])

    algo = nsga.NSGA2(nv, nsga.NSGAConfig(population=12, generations=8, seed=3))
    while not algo.done:
        b = algo.ask()
        algo.tell(f(b), feasible=~slow(b))
    front = algo.archive.frontier()
    assert front and not any(x in algo.archive.infeasible for x, _, _ in front)
    xs, F = algo.archive.arrays()
    ok = algo.archive.feasible_mask(xs)
    exact = {x for x, m in zip([x for x, o in zip(xs, ok, strict=True) if o],
                               nsga.non_dominated_mask(F[ok]), strict=True) if m}
    assert {x for x, _, _ in front} == exact
    everything = nsga.Archive()
    for x, fx in zip(xs, F, strict=True):
        everything.add(x, fx, feasible=False)
    assert {x for x, _, _ in everything.frontier()} == {
        x for x, m in zip(xs, nsga.non_dominated_mask(F), strict=True) if m}
    with pytest.raises(ValueError, match="feasibility"):
        a = nsga.NSGA2(nv)
        a.tell(f(a.ask()), feasible=[True])
