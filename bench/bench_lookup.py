"""Runtime lookup + temporal filter time per query (target <= 50 us).

Uses a store file when given (e.g. one written by `render-budget optimize`), otherwise a generated
store of the same shape as the paper's (depth 4, a few hundred corners, 16-point frontiers, frame times
with the costliest settings of most frontiers missing 30 fps); the lookup cost
depends on the octree and frontier sizes, not on where the frontiers came from.

Run: .venv/bin/python bench/bench_lookup.py [STORE.json] [--queries N] [--reference] [--priority P]
         [--budget-points]

``--reference`` times the lookup this one replaced (kept in tests/store_reference.py as the slow
reference the property tests compare with) on the same queries, in the same process. ``--priority``
passes the query's priority ("frame_rate" or "budget"; not passed when omitted, so the script also
times trees from before the option); the last column says how many of the queries were answered with a
setting that misses the frame rate (under "budget": where no real-time setting keeps the budget).
``--budget-points`` also lists each query's allowed points (``ParetoStore.budget_points``, what playback
hands the temporal filter on every frame; not for ``--reference``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from service.store import Frontier, ParetoStore, StoredParameter, TemporalFilter, pack_array
from service.store.camera import look_matrix


def generated_store(depth: int = 4, seed: int = 0) -> ParetoStore:
    """Octree refined around a diagonal line through the root, frontiers of 16 points."""
    rng = np.random.default_rng(seed)
    side = 1 << depth
    nodes = [((0, 0, 0), side)]
    children = [-1]
    corners: dict[tuple[int, int, int], int] = {}

    def add_corners(o, s):
        for k in range(8):
            xyz = (o[0] + s * (k & 1), o[1] + s * ((k >> 1) & 1), o[2] + s * ((k >> 2) & 1))
            corners.setdefault(xyz, len(corners))

    add_corners((0, 0, 0), side)
    level = [0]
    for _ in range(depth):
        nxt = []
        for n in level:
            (x, y, z), s = nodes[n]
            c = np.array([x, y, z]) + s / 2
            if np.linalg.norm(c - c.mean()) > s:  # refine only near the diagonal
                continue
            children[n] = len(nodes)
            h = s // 2
            for k in range(8):
                o = (x + h * (k & 1), y + h * ((k >> 1) & 1), z + h * ((k >> 2) & 1))
                nodes.append((o, h))
                children.append(-1)
                add_corners(o, h)
                nxt.append(len(nodes) - 1)
        level = nxt
    n_fr = len(corners) * 2
    frontiers = []
    timing = np.random.default_rng(seed + 1)  # own stream: settings, errors and powers as they were
    for _ in range(n_fr):
        idx = rng.integers(0, 4, size=(16, 8))
        fr = Frontier.from_points(pack_array(idx), np.sort(rng.uniform(0, 0.2, 16))[::-1],
                                  np.sort(rng.uniform(0.5, 3, 16)))
        frame_time = np.sort(timing.uniform(0.002, 0.05, len(fr)))  # 30 fps: a period of 33 ms
        frontiers.append(Frontier(fr.packed, fr.error, fr.power_w, frame_time))
    views = rng.integers(0, n_fr, size=(len(corners), 6))
    params = tuple(StoredParameter(f"p{i}", (0, 1, 2, 3), 3) for i in range(8))
    coords = np.zeros((len(corners), 3), dtype=np.int64)
    for xyz, i in corners.items():
        coords[i] = xyz
    return ParetoStore(params, np.zeros(3), 10.0, depth, np.asarray(children), coords, views, frontiers)


def _queries(store: ParetoStore, n: int) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]:
    """A smooth camera path through the root (positions), random view directions, the same poses as
    camera matrices, and budgets that vary."""
    rng = np.random.default_rng(1)
    lo, size = store.root_min, store.root_size
    t = np.linspace(0, 1, n)
    pos = lo + size * np.stack([t, 0.5 + 0.3 * np.sin(6 * t), 0.5 + 0.3 * np.cos(4 * t)], axis=1)
    dirs = rng.normal(size=(n, 3))
    mats = [look_matrix(p, d) for p, d in zip(pos, dirs, strict=True)]
    return pos, dirs, mats, rng.uniform(0.5, 3.0, n)


def _time(lookup: Any, cases: tuple, queries: tuple, repeat: int, extra: dict | None = None,
          points: Any = None) -> list[tuple[str, float, float, int]]:
    """(label, CPU us, wall us, queries answered with a setting that misses the frame rate) per case:
    the best of ``repeat`` runs by CPU time (other processes on a shared machine only ever add time);
    ``extra``: more keyword arguments of every query; ``points``: called with each result too (the
    allowed points)."""
    pos, dirs, mats, budgets = queries
    more = extra or {}
    out = []
    for label, with_filter, kind in cases:
        runs = []
        slow = 0
        for _ in range(repeat):
            filt = TemporalFilter(2.0)
            slow = 0
            w0, c0 = time.perf_counter(), time.process_time()
            for i in range(len(pos)):
                kw = {"power_budget": budgets[i]} if kind != "e" else {"error_budget": budgets[i] / 20}
                pose = {"matrix": mats[i]} if kind == "m" else {"direction": dirs[i]}
                r = lookup(pos[i], **pose, **kw, **more)
                if points is not None:
                    points(r)
                if with_filter:
                    filt.update(r[0] if isinstance(r, tuple) else r.indices, i / 60.0)
                slow += (r[-1] if isinstance(r, tuple) else r.meets_fps) is False
            runs.append(((time.process_time() - c0) / len(pos), (time.perf_counter() - w0) / len(pos)))
        cpu, wall = min(runs)
        out.append((label, cpu * 1e6, wall * 1e6, slow))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("store", nargs="?", type=Path)
    ap.add_argument("--queries", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=3, help="runs per row; the best CPU time is reported")
    ap.add_argument("--reference", action="store_true",
                    help="also time the lookup this one replaced (tests/store_reference.py), same queries")
    ap.add_argument("--priority", choices=("frame_rate", "budget"),
                    help="the query's priority (default: not passed)")
    ap.add_argument("--budget-points", action="store_true",
                    help="also list each query's allowed points (budget_points), as playback does")
    args = ap.parse_args()
    store = ParetoStore.from_json(args.store.read_bytes()) if args.store else generated_store()
    st = store.stats()
    print(f"store: {st['size_bytes'] / 1024:.1f} KB, depth {st['depth']}, {st['leaves']} leaves, "
          f"{st['corners']} corners, {st['unique_frontiers']} frontiers, {st['frontier_points']} points")
    queries = _queries(store, args.queries)
    cases = (("lookup (power budget)", False, "p"), ("lookup (error budget)", False, "e"),
             ("lookup + temporal filter", True, "p"), ("lookup by matrix + filter", True, "m"))
    rows = _time(store.lookup, cases, queries, args.repeat,
                 None if args.priority is None else {"priority": args.priority},
                 store.budget_points if args.budget_points else None)
    ref = None
    if args.reference:
        sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
        from tests.store_reference import ReferenceLookup

        ref = _time(ReferenceLookup(store).lookup, cases, queries, args.repeat)
    head = f"{'query':>28} {'CPU us':>8} {'wall us':>8} {'missing fps':>11}"
    print(head + (f" {'ref CPU us':>11} {'ref wall':>9} {'speed-up':>9}" if ref else ""))
    for k, (label, cpu, wall, slow) in enumerate(rows):
        line = f"{label:>28} {cpu:8.1f} {wall:8.1f} {slow:11d}"
        if ref:
            line += f" {ref[k][1]:11.1f} {ref[k][2]:9.1f} {ref[k][1] / cpu:8.1f}x"
        print(line)
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
