"""Where a main-job run's mean |predicted - measured| error comes from, per budget mode, from the run's
own files (no renders): ``OUT/per_frame.csv`` (the settings shown and what they measured),
``OUT/store.json``, ``OUT/summary.json`` (budgets, frame step) and the scene's camera path.

The playback driver is stepped over every path frame as the evaluation stepped it
(``addon.core.evaluate_path.filtered_frames``) and, on every evaluated frame, the shown point's error is
taken three ways:

- *stored*: the frontier's figure, the worst over the cameras the frontier was priced at (its sample and
  guard frames): what the budget is checked against, and what the store predicted before it kept
  per-camera figures;
- *expected*: the prediction for the frame's camera (``ParetoStore.expected``: the pricing cameras'
  figures interpolated there), what playback and the report predict now;
- *measured*: per_frame.csv's.

Frames are classed by what could make the prediction miss: the temporal filter in transition (it shows
an allowed point other than the target), and the dissimilarity (``service.store.priced``) from the
frame's camera to the nearest camera its frontier was priced at. Per class: frames, and each column's
share of the mean |x - measured| over all frames; then the frames that contribute most. The stored
column minus the expected one is what taking the worst camera's figure cost; the expected column is
what remains (the setting's error at the frame against its error at the priced cameras nearby).

    .venv/bin/python bench/bench_prediction_split.py hall out/hall_pred_g1

``--around FRAME``: also render the setting the power-budget mode showed on evaluated frame ``FRAME`` at
the path frames around it (the summary's resolution and profile, the store's maximum quality as the
reference, as verify measures): how much that setting's error moves from one frame to the next, which no
prediction from priced cameras a frame or more away can follow.

    .venv/bin/python bench/bench_prediction_split.py hall out/hall_pred_g1 --around 1406

Needs a store with per-camera figures (``store.priced``; path-sampled, priced at display resolution with
guard frames); without them both columns are the stored figure.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from addon.core.evaluate_path import filtered_frames
from service.camera_path import CameraPath
from service.evaluation import CameraSpec, evaluate, load_scene
from service.params import default_space
from service.store import ParetoStore
from service.store.priced import camera_dissimilarity

REPO = Path(__file__).resolve().parents[1]
MODES = {"ours_power": "POWER", "ours_error": "ERROR"}
#: dissimilarity classes (squared eye distance / viewing distance^2 + squared view-direction difference)
NEAR = (1e-4, 0.05)


def split(store: ParetoStore, path: CameraPath, rows: list[dict[str, str]], mode: str, budget: float,
          period_s: float) -> list[dict[str, float | int | bool | str]]:
    numbers = [int(r["frame"]) for r in rows]
    shown = filtered_frames(store, path, numbers, mode, budget, period_s)
    kwargs = {"power_budget": budget} if mode == "POWER" else {"error_budget": budget}
    out = []
    for r in rows:
        n = int(r["frame"])
        f = path.frames[n]
        hit = store.lookup(f.position, matrix=np.asarray(f.matrix_world), fov=f.vfov, aspect=f.aspect,
                           **kwargs)
        pf = shown[n]
        points = {p.indices: p for p in store.budget_points(hit)}
        point = points[pf.active_indices]
        stored = point.error
        expected, _ = store.expected(hit, point)
        pr = None if store.priced is None else store.priced[hit.frontier]
        if pr is None:
            nearest = float("nan")
        else:
            m = np.asarray(f.matrix_world, dtype=np.float64)
            fwd = -m[:3, 2] / np.linalg.norm(m[:3, 2])
            nearest = float(np.min(camera_dissimilarity(m[:3, 3], fwd, pr.eyes, pr.forwards, pr.scale)))
        measured = float(r["error"])
        said = float(r["predicted_error"])
        if abs(said - expected) > 1e-5 and abs(said - stored) > 1e-5:
            raise SystemExit(f"frame {n}: per_frame.csv's prediction {r['predicted_error']} is neither the "
                             f"stored {stored:.6f} nor the expected {expected:.6f} figure: another store?")
        if pf.in_transition:
            where = "in transition"
        elif nearest != nearest:
            where = "(no per-camera figures)"
        elif nearest <= NEAR[0]:
            where = "at a priced camera"
        elif nearest <= NEAR[1]:
            where = f"near one (<= {NEAR[1]})"
        else:
            where = f"far (> {NEAR[1]})"
        out.append({"frame": n, "class": where, "stored": stored, "expected": expected, "measured": measured,
                    "nearest": nearest, "transition": pf.in_transition})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("out", type=Path)
    ap.add_argument("--filter-period", type=float, default=2.0, help="the run's temporal filter T (s)")
    ap.add_argument("--worst", type=int, default=6, help="frames listed per mode")
    ap.add_argument("--around", type=int, default=None, help="render this frame's power-mode setting at "
                                                             "the path frames around it")
    args = ap.parse_args()
    store = ParetoStore.from_json((args.out / "store.json").read_text())
    summary = json.loads((args.out / "summary.json").read_text())
    path = CameraPath.load(REPO / "blend_scenes" / "build" / args.scene / "path.json")
    with open(args.out / "per_frame.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    priced = 0 if store.priced is None else sum(p is not None for p in store.priced)
    print(f"{args.scene}: {len(store.frontiers)} frontiers, {priced} with per-camera figures")
    for name, mode in MODES.items():
        rs = [r for r in rows if r["mode"] == name]
        budget = summary["power_budget_w"] if mode == "POWER" else summary["error_budget"]
        recs = split(store, path, rs, mode, float(budget), args.filter_period)
        n = len(recs)
        ds = np.asarray([abs(x["stored"] - x["measured"]) for x in recs])
        de = np.asarray([abs(x["expected"] - x["measured"]) for x in recs])
        print(f"\n{name} (budget {budget:.4g}), {n} frames: mean |stored - measured| {ds.mean():.4f}, "
              f"|expected - measured| {de.mean():.4f}; the worst camera's figure cost "
              f"{ds.mean() - de.mean():.4f}")
        meas = np.asarray([x["measured"] for x in recs])
        pos = meas > 0
        print(f"mean measured error {meas.mean():.4f}; median |x - measured| / measured: stored "
              f"{np.median(ds[pos] / meas[pos]):.3f}, expected {np.median(de[pos] / meas[pos]):.3f}")
        print("| frames | count | share of mean, stored | share of mean, expected |")
        print("|---|---|---|---|")
        for c in sorted({x["class"] for x in recs}):
            k = [i for i, x in enumerate(recs) if x["class"] == c]
            share_s = 100 * ds[k].sum() / max(ds.sum(), 1e-12)
            share_e = 100 * de[k].sum() / max(de.sum(), 1e-12)
            print(f"| {c} | {len(k)} | {ds[k].sum() / n:.4f} ({share_s:.0f} %) | "
                  f"{de[k].sum() / n:.4f} ({share_e:.0f} %) |")
        print("largest |expected - measured| (frame: stored, expected, measured, nearest dissimilarity):")
        for i in np.argsort(-de, kind="stable")[:args.worst]:
            x = recs[int(i)]
            print(f"  {x['frame']}: {x['stored']:.4f}, {x['expected']:.4f}, {x['measured']:.4f}, "
                  f"{x['nearest']:.3f}{' (in transition)' if x['transition'] else ''}: "
                  f"{de[i] / n:.4f} of the mean")
    if args.around is not None:
        around(args.scene, store, summary, path, rows, args.around)


def around(scene_name: str, store: ParetoStore, summary: dict, path: CameraPath, rows: list[dict[str, str]],
           frame: int, reach: int = 3) -> None:
    row = next(r for r in rows if r["mode"] == "ours_power" and int(r["frame"]) == frame)
    given = dict(kv.split("=", 1) for kv in row["settings"].split(";"))
    space = default_space()
    settings = {}
    for prm in store.parameters:  # the stored values, matched by their text in per_frame.csv
        settings[prm.name] = next(v for v in prm.values if str(v) == given[prm.name])
    idx = space.indices_of(settings)
    best = space.indices_of(store.settings_of([p.max_quality for p in store.parameters]))
    scene = load_scene(REPO / "blend_scenes" / "build" / scene_name / "scene.rbscene")
    w, h = summary["resolution"]
    print(f"\nframe {frame}'s power-mode setting ({row['settings']}) at the frames around it, {w}x{h}:")
    for n in range(max(0, frame - reach), min(len(path), frame + reach)):
        m = np.asarray(path.frames[n].matrix_world, dtype=np.float64)
        cam = CameraSpec.from_matrix(m, path.frames[n].vfov, w, h)
        ev = evaluate(scene, cam, idx, space, profile=store.profile, fps=float(summary["fps_target"]),
                      metric="ssim", reference_indices=best)
        print(f"  {n}: error {ev.error:.4f}, power {ev.power_w:.3f} W")


if __name__ == "__main__":
    main()
