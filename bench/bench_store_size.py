"""Where a store's bytes go, and the same stores re-encoded in the current store format.

For each store file: the bytes of each section of its JSON document (as read: the file's own format
version) and of the same store written again by the current writer (``ParetoStore.from_json`` then
``to_json``), and a check that nothing the store answers changed:

- every decoded array is identical (octree, corners, corner views, frontier settings, error, power and
  frame times, sample cameras, per-camera cameras and figures);
- writing the loaded store as format 5 gives the file's bytes back (for a version-5 file);
- lookups: at every frontier's sample camera and every pricing camera, and at ``--perturbed`` randomly
  moved and turned copies of each, under power budgets (5 from the least to the most power stored, 0
  and twice the most) and error budgets (0, 0.005, 0.01, 0.02, 0.05, 0.2, 1), both priorities, the
  whole ``LookupResult`` (settings, frontier, rank, stored and expected error and power, frame time,
  weights) and every ``budget_points`` entry with its ``expected`` figures compared exactly between
  the file as read and the re-encoded store.

With ``--frame-times-cache CACHE.sqlite3`` (one per store, in order; read only) each store's
per-camera figures get each point's frame time at each pricing camera from the evaluation cache of the
job that priced it (its display pricing's evaluations at the pricing cameras), as the current
optimiser keeps them; the store is then measured with them, and the lookups with and without them are
compared (how many choices the per-frame tiers change: ``changed``).

Run: .venv/bin/python bench/bench_store_size.py STORE.json [STORE.json ...] [--perturbed N] [--seed S]
         [--frame-times-cache CACHE.sqlite3 ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sqlite3
import sys
from pathlib import Path

import numpy as np

from service.store import FORMAT_VERSION, ParetoStore
from service.store import format as store_format

#: Sections of the document, by field (every field not listed is "parameters, meta, scalars").
SECTIONS = (
    ("octree", ("children", "node_splits")),
    ("corners", ("corners",)),
    ("corner views", ("corner_views", "view_dirs")),
    ("frontier settings", ("settings", "frontier_sizes", "frontier_settings")),
    ("frontier figures", ("frontier_error", "frontier_power", "frontier_frame_time", "power_scale",
                          "frame_time_scale")),
    ("sample cameras", ("frontier_eyes", "frontier_dirs")),
    ("per-camera cameras", ("priced_cameras", "priced_scale", "priced_eyes", "priced_dirs")),
    ("per-camera figures", ("priced_error", "priced_power", "priced_error_worst", "priced_error_below",
                            "priced_power_worst", "priced_power_below")),
    ("per-camera frame times", ("priced_frame_time", "priced_frame_time_worst", "priced_frame_time_below")),
)
OTHER = "parameters, meta, scalars"


def section_bytes(text: str) -> dict[str, int]:
    """Bytes of each section of a compact JSON document (each field with its key, colon and comma; the
    braces less the last comma under OTHER): they add up to the document's length."""
    doc = json.loads(text)
    where = {field: name for name, fields in SECTIONS for field in fields}
    out = {name: 0 for name, _ in SECTIONS} | {OTHER: 1}
    for key, value in doc.items():
        item = json.dumps({key: value}, separators=(",", ":"), allow_nan=False)
        out[where.get(key, OTHER)] += len(item) - 2 + 1
    if sum(out.values()) != len(text.encode()):
        raise AssertionError("the sections do not add up to the document (not a compact JSON document?)")
    return out


def assert_same_store(a: ParetoStore, b: ParetoStore) -> None:
    """Every decoded array of two stores identical."""
    for name in ("children", "corner_coords", "corner_views", "frontier_eyes", "frontier_dirs", "view_dirs"):
        x, y = getattr(a, name), getattr(b, name)
        if (x is None) != (y is None) or (x is not None and not np.array_equal(x, y)):
            raise AssertionError(f"{name} differs")
    for x, y in zip(a.frontiers, b.frontiers, strict=True):
        for name in ("packed", "error", "power_w", "frame_time_s"):
            if not np.array_equal(getattr(x, name), getattr(y, name)):
                raise AssertionError(f"a frontier's {name} differs")
    if (a.priced is None) != (b.priced is None):
        raise AssertionError("per-camera figures kept by one store only")
    for x, y in zip(a.priced or [], b.priced or [], strict=True):
        if (x is None) != (y is None):
            raise AssertionError("a frontier's per-camera figures kept by one store only")
        if x is not None and not (x.scale == y.scale and all(
                np.array_equal(getattr(x, n), getattr(y, n)) for n in ("eyes", "forwards", "packed", "error",
                                                                       "power_w"))):
            raise AssertionError("a frontier's per-camera figures differ")
        if x is not None and not ((x.frame_time_s is None) == (y.frame_time_s is None) and (
                x.frame_time_s is None or np.array_equal(x.frame_time_s, y.frame_time_s))):
            raise AssertionError("a frontier's per-camera frame times differ")


def with_cached_frame_times(store: ParetoStore, cache: Path) -> ParetoStore:
    """``store`` with each priced point's frame time at each pricing camera from an evaluation cache
    (opened read only): the evaluations at the store's display size whose camera is the pricing camera
    (eye and direction to 1e-5; the nearest cached camera) and whose settings are the point's. Points
    whose evaluation is missing are an error (the cache is not the one that priced the store)."""
    db = sqlite3.connect(f"file:{cache}?mode=ro", uri=True)
    try:
        rows = db.execute("SELECT camera, packed, frame_time_s FROM evaluations WHERE profile=? AND fps=? "
                          "AND metric LIKE '%display=%'", (store.profile, store.fps)).fetchall()
    finally:
        db.close()
    times: dict[str, dict[int, float]] = {}
    for camera, packed, t in rows:
        times.setdefault(camera, {})[int(packed)] = float(t)
    keys = list(times)
    pose = np.asarray([[float(v) for v in k.split("|")[0].split(",")[:6]] for k in keys])
    out = []
    for pf in store.priced or []:
        if pf is None:
            out.append(None)
            continue
        ft = np.zeros_like(pf.error)
        for k in range(pf.cameras):
            want = np.concatenate([pf.eyes[k], pf.forwards[k]])
            i = int(np.argmin(np.abs(pose - want).max(axis=1)))
            if np.abs(pose[i] - want).max() > 1e-5:
                raise ValueError(f"{cache}: no evaluations at a pricing camera of the store")
            got = times[keys[i]]
            ft[k] = [got[int(p)] for p in pf.packed]
        out.append(dataclasses.replace(pf, frame_time_s=ft))
    return dataclasses.replace(store, priced=out)


def query_cameras(store: ParetoStore, perturbed: int, rng: np.random.Generator) -> list[tuple]:
    """(eye, unit forward): each frontier's sample camera and other pricing cameras (else every corner,
    looking along a fixed direction), and ``perturbed`` moved and turned copies of each."""
    cams: list[tuple] = []
    if store.frontier_eyes is not None:
        cams += list(zip(store.frontier_eyes, store.frontier_dirs, strict=True))
    for pf in store.priced or []:
        if pf is not None:
            cams += list(zip(pf.eyes[1:], pf.forwards[1:], strict=True))
    if not cams:
        cams = [(p, np.array([1.0, 0.3, -0.2]) / np.linalg.norm([1.0, 0.3, -0.2]))
                for p in store.corner_positions()]
    out = []
    for eye, fwd in cams:
        out.append((np.asarray(eye, dtype=np.float64), np.asarray(fwd, dtype=np.float64)))
        for _ in range(perturbed):
            d = np.asarray(fwd, dtype=np.float64) + rng.normal(0.0, 0.15, 3)
            out.append((np.asarray(eye, dtype=np.float64) + rng.normal(0.0, 0.02 * store.root_size, 3),
                        d / np.linalg.norm(d)))
    return out


def queries(store: ParetoStore, cams: list[tuple]) -> list[tuple]:
    """(eye, forward, priority, budget) of every lookup the bench compares."""
    most = max(float(f.power_w.max()) for f in store.frontiers)
    least = min(float(f.power_w.min()) for f in store.frontiers)
    budgets = {"power_budget": [*np.linspace(least, most, 5).tolist(), 0.0, 2.0 * most],
               "error_budget": [0.0, 0.005, 0.01, 0.02, 0.05, 0.2, 1.0]}
    return [(eye, fwd, priority, {mode: b}) for eye, fwd in cams for mode, values in budgets.items()
            for b in values for priority in ("frame_rate", "budget")]


def lookups(store: ParetoStore, cams: list[tuple], asked: list[tuple] | None = None) -> list[str]:
    """Every lookup's result and allowed points with their predictions, as exact text (repr)."""
    out = []
    for eye, fwd, priority, budget in asked or queries(store, cams):
        hit = store.lookup(eye, direction=fwd, priority=priority, **budget)
        points = [(p, store.expected(hit, p)) for p in store.budget_points(hit)]
        out.append(repr((hit, points)))
    return out


def disagreeing_points(store: ParetoStore) -> tuple[int, int]:
    """(points priced at several cameras, of them those that keep up with the store's frame rate at
    some of their cameras only: the points whose tier the per-frame prediction can change)."""
    total = mixed = 0
    for pf in store.priced or []:
        if pf is not None and pf.frame_time_s is not None and pf.cameras > 1:
            meets = pf.frame_time_s <= 1.0 / store.fps
            total += meets.shape[1]
            mixed += int((meets.any(axis=0) & ~meets.all(axis=0)).sum())
    return total, mixed


def changed_choices(a: ParetoStore, b: ParetoStore, asked: list[tuple]) -> tuple[int, int]:
    """(lookups whose setting differs between the stores, of them frame-rate-first error-budget lookups
    that ``a`` answered infeasible and ``b`` within the budget)."""
    changed = kept = 0
    for eye, fwd, priority, budget in asked:
        x = a.lookup(eye, direction=fwd, priority=priority, **budget)
        y = b.lookup(eye, direction=fwd, priority=priority, **budget)
        if x.packed != y.packed:
            changed += 1
            first = priority == "frame_rate" and "error_budget" in budget
            kept += first and x.infeasible and not y.infeasible
    return changed, kept


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("stores", nargs="+", type=Path)
    ap.add_argument("--perturbed", type=int, default=2, help="moved copies of each camera (default 2)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--frame-times-cache", type=Path, action="append", default=[],
                    help="evaluation cache of each store's job (one per store, in order): add per-camera "
                         "frame times from it")
    args = ap.parse_args()
    if args.frame_times_cache and len(args.frame_times_cache) != len(args.stores):
        ap.error("give one --frame-times-cache per store")
    names = [p.parent.name if p.stem == "store" else p.stem for p in args.stores]  # (a job's store.json)
    sections: dict[str, list[tuple[int, int]]] = {name: [] for name, _ in SECTIONS} | {OTHER: []}
    summary = []
    failed = False
    changes = []
    for n, path in enumerate(args.stores):
        text = path.read_text()
        version = json.loads(text).get("version")
        read = ParetoStore.from_json(text)
        store = read
        if args.frame_times_cache:  # as the optimiser now writes it: with per-camera frame times
            store = ParetoStore.from_json(with_cached_frame_times(read, args.frame_times_cache[n]).to_json())
        again = store.to_json()
        back = ParetoStore.from_json(again)
        assert_same_store(store, back)
        if back.to_json() != again:
            raise AssertionError(f"{path.name}: the re-encoded store is not stable")
        v5_same = store_format.to_json(read, 5) == text if version == 5 else None
        before, after = section_bytes(text), section_bytes(again)
        for name in sections:
            sections[name].append((before[name], after[name]))
        cams = query_cameras(store, args.perturbed, np.random.default_rng(args.seed))
        asked = queries(store, cams)
        a, b = lookups(store, cams, asked), lookups(back, cams, asked)
        same = sum(x == y for x, y in zip(a, b, strict=True))
        failed |= same != len(a) or v5_same is False
        summary.append((names[n], version, len(text.encode()), len(again.encode()), v5_same, len(cams),
                        len(a), same))
        if args.frame_times_cache:
            changes.append((names[n], *disagreeing_points(store), len(asked),
                            *changed_choices(read, store, asked)))
    print(f"Bytes per section, as read -> re-encoded (format {FORMAT_VERSION}):\n")
    print("| section | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for name, cells in sections.items():
        print(f"| {name} | " + " | ".join(f"{x:,} -> {y:,}" for x, y in cells) + " |")
    print("\n| store | version read | bytes as read | re-encoded | change | format-5 rewrite "
          "byte-identical | cameras | lookups | identical |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, version, n0, n1, v5, cams, total, same in summary:
        v5_text = "n/a" if v5 is None else "yes" if v5 else "NO"
        print(f"| {name} | {version} | {n0:,} ({n0 / 1024:.1f} KB) | {n1:,} ({n1 / 1024:.1f} KB) | "
              f"{100 * (n1 - n0) / n0:+.1f} % | {v5_text} | {cams:,} | {total:,} | {same:,} |")
    if changes:
        print("\nLookups whose setting the per-camera frame times change (the same queries, the store "
              "without them):\n")
        print("| store | points at several cameras | of them real-time at some cameras only | lookups | "
              "changed | frame rate first, error budget: infeasible -> within |")
        print("|---|---|---|---|---|---|")
        for name, points, mixed, total, changed, kept in changes:
            print(f"| {name} | {points:,} | {mixed:,} | {total:,} | {changed:,} | {kept:,} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
