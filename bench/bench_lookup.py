"""Runtime lookup + temporal filter time per query (target <= 50 us).

Uses a store file when given (e.g. one written by `render-budget optimize`), otherwise a generated
store of the same shape as the paper's (depth 4, a few hundred corners, 16-point frontiers); the lookup
cost depends on the octree and frontier sizes, not on where the frontiers came from.

Run: .venv/bin/python bench/bench_lookup.py [STORE.json] [--queries N]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from service.store import Frontier, ParetoStore, StoredParameter, TemporalFilter, pack_array


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
    for _ in range(n_fr):
        idx = rng.integers(0, 4, size=(16, 8))
        frontiers.append(Frontier.from_points(pack_array(idx), np.sort(rng.uniform(0, 0.2, 16))[::-1],
                                              np.sort(rng.uniform(0.5, 3, 16))))
    views = rng.integers(0, n_fr, size=(len(corners), 6))
    params = tuple(StoredParameter(f"p{i}", (0, 1, 2, 3), 3) for i in range(8))
    coords = np.zeros((len(corners), 3), dtype=np.int64)
    for xyz, i in corners.items():
        coords[i] = xyz
    return ParetoStore(params, np.zeros(3), 10.0, depth, np.asarray(children), coords, views, frontiers)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("store", nargs="?", type=Path)
    ap.add_argument("--queries", type=int, default=20000)
    args = ap.parse_args()
    store = ParetoStore.from_json(args.store.read_bytes()) if args.store else generated_store()
    st = store.stats()
    print(f"store: {st['size_bytes'] / 1024:.1f} KB, depth {st['depth']}, {st['leaves']} leaves, "
          f"{st['corners']} corners, {st['unique_frontiers']} frontiers, {st['frontier_points']} points")
    rng = np.random.default_rng(1)
    lo, size = store.root_min, store.root_size
    # a smooth camera path through the root, budgets that vary
    t = np.linspace(0, 1, args.queries)
    pos = lo + size * np.stack([t, 0.5 + 0.3 * np.sin(6 * t), 0.5 + 0.3 * np.cos(4 * t)], axis=1)
    dirs = rng.normal(size=(args.queries, 3))
    budgets = rng.uniform(0.5, 3.0, args.queries)
    filt = TemporalFilter(2.0)
    rows = []
    cases = (("lookup (power budget)", False, "p"), ("lookup (error budget)", False, "e"),
             ("lookup + temporal filter", True, "p"))
    for label, with_filter, kind in cases:
        t0 = time.perf_counter()
        for i in range(args.queries):
            kw = {"power_budget": budgets[i]} if kind == "p" else {"error_budget": budgets[i] / 20}
            r = store.lookup(pos[i], direction=dirs[i], **kw)
            if with_filter:
                filt.update(r.indices, i / 60.0)
        dt = (time.perf_counter() - t0) / args.queries
        rows.append((label, dt))
    print(f"{'query':>28} {'us/query':>9}")
    for label, dt in rows:
        print(f"{label:>28} {dt * 1e6:9.1f}")


if __name__ == "__main__":
    main()
