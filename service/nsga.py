"""NSGA-II over discrete settings (Deb et al. 2002; power-budget paper sec. 5.1.2), with an archive.

A small own core rather than pymoo's, for three reasons measured in ``bench/bench_nsga.py``: offspring
that were already evaluated anywhere in the run (not only in the current population) are replaced by
unseen settings, so every evaluation buys new information; the archive of every evaluation is the
result (its non-dominated set is the frontier); and the ask/tell loop takes batches of index tuples,
which go straight to the evaluation cache and the executor. Everything is driven by one seeded
``numpy.random.Generator``: the same seed gives the same frontier.

Objectives are minimised; rows of ``F`` are points, columns objectives (here: error, power). A point
may also be *infeasible* (here: its frame time misses the target frame rate): Deb's constrained
domination then ranks every feasible point ahead of every infeasible one, and the points of each group
by their own non-dominated fronts (:func:`constrained_fronts`); the archive's frontier is that of the
feasible points when there are any.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

Indices = tuple[int, ...]


# ----------------------------------------------------------------------------------------------------
# Sorting, crowding, hypervolume


def dominates(a: np.ndarray, b: np.ndarray) -> bool:
    """``a`` is no worse than ``b`` everywhere and better somewhere (the paper's partial order)."""
    return bool(np.all(a <= b) and np.any(a < b))


def non_dominated_sort(F: np.ndarray) -> list[np.ndarray]:
    """Fronts of ``F`` (N, M) as index arrays, best first (fast non-dominated sort, O(M N^2)).

    Equal points share a front (neither dominates the other)."""
    F = np.asarray(F, dtype=np.float64)
    if F.ndim != 2:
        raise ValueError("F must be (N, M)")
    n = F.shape[0]
    if n == 0:
        return []
    if not np.all(np.isfinite(F)):
        raise ValueError("objectives must be finite")
    le = np.all(F[:, None, :] <= F[None, :, :], axis=2)
    lt = np.any(F[:, None, :] < F[None, :, :], axis=2)
    dom = le & lt  # dom[i, j]: i dominates j
    count = dom.sum(axis=0)  # how many dominate j
    fronts = []
    current = np.flatnonzero(count == 0)
    while current.size:
        fronts.append(current)
        count = count - dom[current].sum(axis=0)
        count[current] = -1
        for f in fronts:
            count[f] = -1
        current = np.flatnonzero(count == 0)
    return fronts


def constrained_fronts(F: np.ndarray, feasible: np.ndarray | None = None) -> list[np.ndarray]:
    """Fronts under constrained domination (Deb 2002): the feasible points' fronts first, then the
    infeasible points' (each group sorted by its own objectives); ``feasible=None``: all feasible."""
    F = np.asarray(F, dtype=np.float64)
    if feasible is None or bool(np.all(feasible)):
        return non_dominated_sort(F)
    ok = np.flatnonzero(feasible)
    bad = np.flatnonzero(~np.asarray(feasible, dtype=bool))
    return ([ok[f] for f in non_dominated_sort(F[ok])] if ok.size else []) + [
        bad[f] for f in non_dominated_sort(F[bad])]


def rank_of(F: np.ndarray, feasible: np.ndarray | None = None) -> np.ndarray:
    """Front number of every point (0 = non-dominated), feasible points ahead of infeasible ones."""
    rank = np.empty(np.asarray(F).shape[0], dtype=np.int64)
    for r, f in enumerate(constrained_fronts(F, feasible)):
        rank[f] = r
    return rank


def non_dominated_mask(F: np.ndarray) -> np.ndarray:
    """Boolean mask of the points no other point dominates."""
    F = np.asarray(F, dtype=np.float64)
    if F.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    if F.shape[1] == 2:
        return _non_dominated_mask_2d(F)
    le = np.all(F[:, None, :] <= F[None, :, :], axis=2)
    lt = np.any(F[:, None, :] < F[None, :, :], axis=2)
    return ~np.any(le & lt, axis=0)


def _non_dominated_mask_2d(F: np.ndarray) -> np.ndarray:
    """O(N log N) sweep: in (f0, f1) order a point is dominated iff an earlier point has a smaller f1,
    or the same f1 with a smaller f0 (equal points never dominate each other)."""
    order = np.lexsort((F[:, 1], F[:, 0]))
    f0 = F[order, 0].tolist()
    f1 = F[order, 1].tolist()
    mask_sorted = np.ones(len(order), dtype=bool)
    best1 = math.inf
    best0 = math.inf  # smallest f0 reaching best1
    for k in range(len(order)):
        a, b = f0[k], f1[k]
        if best1 < b or (best1 == b and best0 < a):
            mask_sorted[k] = False
        if b < best1:
            best1, best0 = b, a
    mask = np.empty_like(mask_sorted)
    mask[order] = mask_sorted
    return mask


def crowding_distance(F: np.ndarray) -> np.ndarray:
    """Deb's crowding distance of the points of one front: boundary points get ``inf``; inner points the
    sum over objectives of the normalised gap between their neighbours (stable sort, so ties are
    ordered by index and the result is deterministic). An objective with zero range adds nothing."""
    F = np.asarray(F, dtype=np.float64)
    n, m = F.shape
    d = np.zeros(n)
    if n <= 2:
        d[:] = np.inf
        return d
    for j in range(m):
        order = np.argsort(F[:, j], kind="stable")
        f = F[order, j]
        span = f[-1] - f[0]
        d[order[0]] = np.inf
        d[order[-1]] = np.inf
        if span > 0:
            d[order[1:-1]] += (f[2:] - f[:-2]) / span
    return d


def hypervolume_2d(F: np.ndarray, ref: Sequence[float]) -> float:
    """Area dominated by the 2-D points ``F`` and bounded by the reference point (minimisation)."""
    F = np.asarray(F, dtype=np.float64).reshape(-1, 2)
    r0, r1 = float(ref[0]), float(ref[1])
    F = F[(F[:, 0] < r0) & (F[:, 1] < r1)]
    if F.shape[0] == 0:
        return 0.0
    order = np.lexsort((F[:, 1], F[:, 0]))
    area = 0.0
    best1 = r1
    for i in order:
        x, y = F[i]
        if y < best1:
            area += (r0 - x) * (best1 - y)
            best1 = y
    return float(area)


# ----------------------------------------------------------------------------------------------------
# The optimiser


@dataclass
class NSGAConfig:
    """Options of one per-camera search. ``generations`` counts the initial population (pymoo's n_gen)."""

    population: int = 24
    generations: int = 25
    crossover_prob: float = 0.9
    mutation_prob: float | None = None  # per parameter; None -> 1 / number of parameters
    seed: int = 0

    def __post_init__(self) -> None:
        if self.population < 2:
            raise ValueError("population must be >= 2")
        if self.generations < 1:
            raise ValueError("generations must be >= 1")
        if not 0 <= self.crossover_prob <= 1:
            raise ValueError("crossover_prob must be in [0, 1]")


@dataclass
class Archive:
    """Every evaluated point of a search: settings (index tuples), objectives and feasibility, in
    evaluation order."""

    points: dict[Indices, tuple[float, float]] = field(default_factory=dict)
    infeasible: set[Indices] = field(default_factory=set)

    def add(self, x: Indices, f: Sequence[float], feasible: bool = True) -> None:
        key = tuple(int(v) for v in x)
        if key not in self.points:
            self.points[key] = (float(f[0]), float(f[1]))
            if not feasible:
                self.infeasible.add(key)

    def feasible_mask(self, xs: Sequence[Indices]) -> np.ndarray:
        return np.asarray([x not in self.infeasible for x in xs], dtype=bool)

    def __contains__(self, x: object) -> bool:
        return x in self.points

    def __len__(self) -> int:
        return len(self.points)

    def arrays(self) -> tuple[list[Indices], np.ndarray]:
        xs = list(self.points)
        F = np.asarray([self.points[x] for x in xs], dtype=np.float64).reshape(-1, 2)
        return xs, F

    def frontier(self) -> list[tuple[Indices, float, float]]:
        """Non-dominated points, power ascending (ties in both objectives: first evaluated kept): of the
        feasible points when there are any, else of all."""
        xs, F = self.arrays()
        if not xs:
            return []
        feasible = self.feasible_mask(xs)
        if feasible.any() and not feasible.all():
            xs = [x for x, ok in zip(xs, feasible, strict=True) if ok]
            F = F[feasible]
        mask = non_dominated_mask(F)
        seen: set[tuple[float, float]] = set()
        out = []
        for i in np.flatnonzero(mask):
            key = (F[i, 0], F[i, 1])
            if key not in seen:
                seen.add(key)
                out.append((xs[i], float(F[i, 0]), float(F[i, 1])))
        out.sort(key=lambda t: (t[2], t[1]))
        return out


def space_size(n_values: Sequence[int]) -> int:
    return math.prod(int(v) for v in n_values)


def enumerate_space(n_values: Sequence[int]) -> list[Indices]:
    """Every index tuple of the space, parameter 0 varying slowest."""
    return [tuple(x) for x in itertools.product(*(range(int(v)) for v in n_values))]


class NSGA2:
    """Discrete NSGA-II with an ask/tell loop and archive-wide duplicate elimination.

    ``ask()`` returns settings never asked before; ``tell(F)`` gives their objectives in the same order.
    ``initial`` (warm start, e.g. the parent node's frontier) seeds the first population."""

    def __init__(self, n_values: Sequence[int], config: NSGAConfig | None = None,
                 initial: Iterable[Sequence[int]] = ()) -> None:
        self.n_values = np.asarray([int(v) for v in n_values], dtype=np.int64)
        if self.n_values.size == 0 or np.any(self.n_values < 1):
            raise ValueError("every parameter needs at least one value")
        self.config = config or NSGAConfig()
        self.rng = np.random.default_rng(self.config.seed)
        self.size = space_size(self.n_values.tolist())
        self.archive = Archive()
        self.generation = 0
        self._pending: list[Indices] | None = None
        self._pop: list[Indices] = []
        self._initial = [tuple(int(v) for v in x) for x in initial]
        for x in self._initial:
            if len(x) != self.n_values.size or any(not 0 <= v < n for v, n in zip(x, self.n_values,
                                                                                   strict=True)):
                raise ValueError(f"warm-start point {x} is outside the space")
        pm = self.config.mutation_prob
        self.mutation_prob = 1.0 / self.n_values.size if pm is None else float(pm)

    @property
    def done(self) -> bool:
        return self.generation >= self.config.generations or len(self.archive) >= self.size

    def _random_point(self) -> Indices:
        return tuple(int(self.rng.integers(0, n)) for n in self.n_values)

    def _fill_unseen(self, out: list[Indices], want: int, taken: set[Indices]) -> None:
        """Append unseen random points until ``want`` (rejection sampling, then a scan for tiny spaces)."""
        tries = 0
        while len(out) < want and tries < 50 * want:
            x = self._random_point()
            tries += 1
            if x not in taken and x not in self.archive:
                taken.add(x)
                out.append(x)
        if len(out) < want:
            free = [x for x in enumerate_space(self.n_values.tolist()) if x not in taken and x not in
                    self.archive]
            pick = self.rng.permutation(len(free))[: want - len(out)]
            for i in sorted(pick.tolist()):
                taken.add(free[i])
                out.append(free[i])

    def _tournament(self, rank: np.ndarray, crowd: np.ndarray) -> int:
        a, b = (int(v) for v in self.rng.integers(0, rank.size, size=2))
        if rank[a] != rank[b]:
            return a if rank[a] < rank[b] else b
        if crowd[a] != crowd[b]:
            return a if crowd[a] > crowd[b] else b
        return a

    def _offspring(self) -> list[Indices]:
        pop = self._pop
        F = np.asarray([self.archive.points[x] for x in pop])
        feasible = self.archive.feasible_mask(pop)
        rank = rank_of(F, feasible)
        crowd = np.zeros(len(pop))
        for front in constrained_fronts(F, feasible):
            crowd[front] = crowding_distance(F[front])
        want = min(self.config.population, self.size - len(self.archive))
        out: list[Indices] = []
        taken: set[Indices] = set()
        attempts = 0
        while len(out) < want and attempts < 20 * want:
            attempts += 1
            p1 = np.asarray(pop[self._tournament(rank, crowd)])
            p2 = np.asarray(pop[self._tournament(rank, crowd)])
            c1, c2 = p1.copy(), p2.copy()
            if self.rng.random() < self.config.crossover_prob:
                swap = self.rng.random(p1.size) < 0.5  # uniform crossover: swap parameter values
                c1[swap], c2[swap] = p2[swap], p1[swap]
            for c in (c1, c2):
                mut = self.rng.random(c.size) < self.mutation_prob
                for j in np.flatnonzero(mut):
                    n = int(self.n_values[j])
                    if n < 2:
                        continue
                    if self.rng.random() < 0.5:  # ordered values: a neighbouring step ...
                        step = 1 if self.rng.random() < 0.5 else -1
                        c[j] = min(max(int(c[j]) + step, 0), n - 1)
                    else:  # ... or any other value
                        c[j] = (int(c[j]) + int(self.rng.integers(1, n))) % n
                x = tuple(int(v) for v in c)
                if len(out) < want and x not in taken and x not in self.archive:
                    taken.add(x)
                    out.append(x)
        self._fill_unseen(out, want, taken)
        return out

    def ask(self) -> list[Indices]:
        """The next batch of unseen settings to evaluate (empty when done)."""
        if self._pending is not None:
            raise RuntimeError("tell() the previous batch first")
        if self.done:
            return []
        if self.generation == 0:
            want = min(self.config.population, self.size)
            out: list[Indices] = []
            taken: set[Indices] = set()
            for x in self._initial:
                if len(out) < want and x not in taken:
                    taken.add(x)
                    out.append(x)
            self._fill_unseen(out, want, taken)
        else:
            out = self._offspring()
        self._pending = out
        return list(out)

    def tell(self, F: np.ndarray | Sequence[Sequence[float]], feasible: Sequence[bool] | None = None) -> None:
        """Objectives (N, 2) of the last ``ask()`` batch, same order, and whether each point is feasible
        (None: all are)."""
        if self._pending is None:
            raise RuntimeError("ask() first")
        arr = np.asarray(F, dtype=np.float64).reshape(-1, 2)
        if arr.shape[0] != len(self._pending):
            raise ValueError("tell() got a different number of results than ask() gave")
        if not np.all(np.isfinite(arr)):
            raise ValueError("objectives must be finite")
        ok = [True] * arr.shape[0] if feasible is None else [bool(v) for v in feasible]
        if len(ok) != arr.shape[0]:
            raise ValueError("tell() got a different number of feasibility flags than results")
        for x, f, good in zip(self._pending, arr, ok, strict=True):
            self.archive.add(x, f, good)
        merged = list(dict.fromkeys(self._pop + self._pending))
        self._pending = None
        self._pop = self._survive(merged)
        self.generation += 1

    def _survive(self, cand: list[Indices]) -> list[Indices]:
        """Rank-and-crowding survival (Deb 2002) down to the population size."""
        k = self.config.population
        if len(cand) <= k:
            return cand
        F = np.asarray([self.archive.points[x] for x in cand])
        keep: list[int] = []
        for front in constrained_fronts(F, self.archive.feasible_mask(cand)):
            if len(keep) + front.size <= k:
                keep.extend(front.tolist())
                if len(keep) == k:
                    break
                continue
            d = crowding_distance(F[front])
            order = np.argsort(-d, kind="stable")
            keep.extend(front[order[: k - len(keep)]].tolist())
            break
        return [cand[i] for i in keep]


def optimise(evaluate: Callable[[list[Indices]], np.ndarray], n_values: Sequence[int],
             config: NSGAConfig | None = None, initial: Iterable[Sequence[int]] = (),
             exhaustive_limit: int = 512, should_cancel: Callable[[], bool] | None = None) -> Archive:
    """Frontier search for one camera: exhaustive when the space has <= ``exhaustive_limit`` settings
    (the frontier is then exact), NSGA-II otherwise. ``evaluate`` maps a batch to (N, 2) objectives."""
    cfg = config or NSGAConfig()
    size = space_size(n_values)
    if size <= exhaustive_limit:
        xs = enumerate_space(n_values)
        archive = Archive()
        for start in range(0, len(xs), max(cfg.population, 1) * 4):
            if should_cancel is not None and should_cancel():
                break
            batch = xs[start:start + max(cfg.population, 1) * 4]
            for x, f in zip(batch, np.asarray(evaluate(batch)).reshape(-1, 2), strict=True):
                archive.add(x, f)
        return archive
    algo = NSGA2(n_values, cfg, initial)
    while not algo.done:
        if should_cancel is not None and should_cancel():
            break
        batch = algo.ask()
        if not batch:
            break
        algo.tell(evaluate(batch))
    return algo.archive
