"""NSGA-II on a real 16,384-setting render space: hypervolume against unique renders.

Compares, on the same camera and the same cached renders: our core (archive frontier, duplicate
elimination against the whole archive, both ends of the space seeded), our core warm-started from a
neighbouring camera's frontier (what the octree does), plain pymoo NSGA-II (integer SBX/PM with
rounding repair, eliminate_duplicates, frontier = its final population; and the same run's archive),
and random sampling. The exact frontier comes from rendering all 16,384 settings. Hypervolume uses
objectives normalised by the whole space's extremes and the reference point (1, 1).

Run: .venv/bin/python bench/bench_nsga.py [--width 32 --height 24 --seeds 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from service import nsga
from service.eval_cache import EvalCache
from service.evaluation import CameraSpec, Evaluator
from service.params import Parameter, ParameterSpace

# The search's test scene is shared with the tests (tests/tracer_scenes.py).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from tracer_scenes import teapot_scene


def space_16k() -> ParameterSpace:
    """4^6 x 2 x 2 = 16,384 settings of the tracer (values cheapest first)."""
    samp = (("undersample_4x4", {"mode": "undersample", "block": 4}),
            ("undersample_2x2", {"mode": "undersample", "block": 2}),
            ("1spp", {"mode": "1spp", "block": 2}),
            ("fsaa_2x2", {"mode": "fsaa", "block": 2}))
    return ParameterSpace((
        Parameter("sampling", tuple(n for n, _ in samp), 3, tuple(f for _, f in samp)),
        Parameter("normal_threshold_deg", (60.0, 30.0, 15.0, 5.0), 3),
        Parameter("max_depth", (0, 1, 2, 3), 3),
        Parameter("shadow_samples", (0, 1, 4, 16), 3),
        Parameter("resolution_scale", (0.7, 0.8, 0.9, 1.0), 3),
        Parameter("ao_samples", (0, 4, 8, 16), 3),
        Parameter("multirate", (True, False), 1),
        Parameter("tile_size", (32, 16), 1),
    ))


class Counted:
    """Objective function over a cache of all renders, counting the distinct settings asked for."""

    def __init__(self, table: dict[tuple[int, ...], tuple[float, float]]) -> None:
        self.table = table
        self.seen: list[tuple[int, ...]] = []
        self._set: set[tuple[int, ...]] = set()

    def __call__(self, batch) -> np.ndarray:
        out = []
        for x in batch:
            x = tuple(int(v) for v in x)
            if x not in self._set:
                self._set.add(x)
                self.seen.append(x)
            out.append(self.table[x])
        return np.asarray(out, dtype=np.float64)


def hv(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    P = P[nsga.non_dominated_mask(P)]
    return nsga.hypervolume_2d((P - lo) / (hi - lo), (1.0, 1.0))


def run_pymoo(f: Counted, n_values, seed: int, pop: int, gens: int, eta: tuple[float, float] = (3.0, 3.0),
              prob: float = 1.0) -> np.ndarray:
    from pymoo.algorithms.moo.nsga2 import NSGA2 as PymooNSGA2
    from pymoo.core.evaluator import Evaluator as PymooEvaluator
    from pymoo.core.problem import Problem
    from pymoo.operators.crossover.sbx import SBX
    from pymoo.operators.mutation.pm import PM
    from pymoo.operators.repair.rounding import RoundingRepair
    from pymoo.operators.sampling.rnd import IntegerRandomSampling
    from pymoo.problems.static import StaticProblem

    xu = np.asarray(n_values) - 1
    problem = Problem(n_var=len(n_values), n_obj=2, xl=np.zeros(len(n_values)), xu=xu, vtype=int)
    algo = PymooNSGA2(pop_size=pop, sampling=IntegerRandomSampling(),
                      crossover=SBX(prob=prob, eta=eta[0], vtype=float, repair=RoundingRepair()),
                      mutation=PM(prob=1.0, eta=eta[1], vtype=float, repair=RoundingRepair()),
                      eliminate_duplicates=True)
    algo.setup(problem, termination=("n_gen", gens), seed=seed, verbose=False)
    while algo.has_next():
        popn = algo.ask()
        X = np.asarray(popn.get("X")).round().astype(int)
        F = f([tuple(x) for x in X])
        PymooEvaluator().eval(StaticProblem(problem, F=F), popn)
        algo.tell(infills=popn)
    return np.asarray(algo.result().F)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=32)
    ap.add_argument("--height", type=int, default=24)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--cache", type=Path, default=None, help="SQLite cache to reuse the exhaustive renders")
    args = ap.parse_args()
    scene = teapot_scene()
    sp = space_16k()
    cam = CameraSpec((0.0, -9.0, 5.0), (0.0, 9.0, -4.0), (0.0, 0.0, 1.0), 0.7, args.width, args.height)
    near = CameraSpec((0.8, -8.6, 5.2), (-0.8, 8.6, -4.2), (0.0, 0.0, 1.0), 0.7, args.width, args.height)
    ev = Evaluator(scene, sp, cache=EvalCache(args.cache), target_pixels=1920 * 1080)
    xs = nsga.enumerate_space(sp.free_n_values)
    t0 = time.perf_counter()
    res = ev.evaluate([(cam, sp.expand(x)) for x in xs])
    t_all = time.perf_counter() - t0
    table = {x: (r.error, r.power_w) for x, r in zip(xs, res, strict=True)}
    F = np.asarray(list(table.values()))
    lo, hi = F.min(axis=0), F.max(axis=0)
    exact = hv(F, lo, hi)
    print(f"space: {sp.size} settings, {args.width}x{args.height}; exhaustive renders took {t_all:.1f} s "
          f"({ev.evaluations} rendered now, {ev.cache_hits} from cache); exact frontier "
          f"{int(nsga.non_dominated_mask(F).sum())} points")
    nv = sp.free_n_values
    ends = [sp.restrict(sp.max_quality_indices()), sp.restrict(sp.min_quality_indices())]

    # warm start: our search's frontier at a nearby camera
    ev_near = Evaluator(scene, sp, cache=EvalCache(args.cache), target_pixels=1920 * 1080)

    def f_near(batch):
        r = ev_near.evaluate([(near, sp.expand(x)) for x in batch])
        return np.asarray([(a.error, a.power_w) for a in r])

    near_front = [x for x, _, _ in nsga.optimise(f_near, nv, nsga.NSGAConfig(seed=99), initial=ends,
                                                 exhaustive_limit=0).frontier()]

    rows: dict[str, list[tuple[int, float]]] = {}
    checkpoints = (100, 200, 300, 400, 500)
    curves: dict[str, list[list[float]]] = {}
    for seed in range(args.seeds):
        for name in ("ours", "ours + warm start", "pymoo NSGA-II (final pop.)", "pymoo NSGA-II (archive)",
                     "pymoo, default etas (archive)", "random sampling"):
            f = Counted(table)
            if name.startswith("ours"):
                init = ends + (near_front if "warm" in name else [])
                arch = nsga.optimise(f, nv, nsga.NSGAConfig(population=24, generations=25, seed=seed),
                                     initial=init, exhaustive_limit=0)
                front = np.asarray([(e, p) for _, e, p in arch.frontier()])
            elif name.startswith("pymoo"):
                if "default" in name:  # SBX eta 15 (prob 0.9), PM eta 20: pymoo's own defaults
                    run_pymoo(f, nv, seed, 24, 25, eta=(15.0, 20.0), prob=0.9)
                    front = np.asarray([table[x] for x in f.seen])
                elif "archive" in name:
                    run_pymoo(f, nv, seed, 24, 25)
                    front = np.asarray([table[x] for x in f.seen])
                else:
                    front = run_pymoo(f, nv, seed, 24, 25)
            else:
                rng = np.random.default_rng(seed)
                pick = rng.choice(len(xs), size=500, replace=False)
                f([xs[i] for i in pick])
                front = np.asarray([table[x] for x in f.seen])
            rows.setdefault(name, []).append((len(f.seen), hv(front, lo, hi) / exact))
            if "final" not in name:
                curve = []
                for c in checkpoints:
                    pts = np.asarray([table[x] for x in f.seen[:c]])
                    curve.append(hv(pts, lo, hi) / exact if len(pts) else 0.0)
                curves.setdefault(name, []).append(curve)
    print(f"\n{'method (pop 24 x 25 gens)':>30} {'unique renders':>15} {'HV / exact (mean)':>18} {'min':>7}")
    for name, vals in rows.items():
        n = np.mean([v[0] for v in vals])
        h = [v[1] for v in vals]
        print(f"{name:>30} {n:15.0f} {np.mean(h):18.4f} {np.min(h):7.4f}")
    print(f"\nHV / exact after N unique renders (mean over {args.seeds} seeds)")
    print(f"{'method':>30} " + " ".join(f"{c:>7}" for c in checkpoints))
    for name, cs in curves.items():
        m = np.mean(np.asarray(cs), axis=0)
        print(f"{name:>30} " + " ".join(f"{v:7.4f}" for v in m))


if __name__ == "__main__":
    main()
