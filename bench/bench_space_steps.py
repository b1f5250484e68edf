"""Where a scene's setting space jumps in error, and where its dynamic power goes: Max, every single-
parameter step down from Max, candidate in-between values, the Max-Mid preset and a greedy descent to the
cheapest setting within an error budget, all priced as whole frames at display resolution.

Each setting is rendered whole at the display size and priced with the product's own functions (what
``service.display_pricing`` does with ``DisplayPricing("full")``): error = 1 - SSIM after the display
transform against Max at the same size (``service.evaluation.image_error``), power = what the profile's
GPU draws at the frame rate the frame reaches (``service.evaluation._price``). Cameras are path frames
spread evenly along the path.

    .venv/bin/python bench/bench_space_steps.py chess --profile desktop --size 320x180 --cameras 4

Candidate values (``--candidates``) are settings outside the default space, named ``parameter=value``
(the values below); ``--greedy`` also walks down from Max one step at a time (each step the cheapest
single-parameter step down whose mean error over the cameras stays within ``--budget``) and prints the
path it took.

``--neighbourhood K`` answers whether the space holds settings that keep the frame rate within the error
budget at given path frames (``--frames``): every setting within L1 index distance K of Max (the sum over
parameters of how many steps each is below its maximum-quality value; parameters the simulator reports
inert for the scene stay at Max, as in the product's search) is priced at every frame, and per frame it
prints how many keep ``--fps`` and ``--budget``, the cheapest of them and the most accurate setting that
keeps ``--fps``. Settings that differ only in the normal threshold or multi-rate under a non-adaptive
sampling mode (FSAA, 1 spp), which the renderer does not read there, are rendered once (checked on the
first frame at start). The answer is exact for the neighbourhood; ``--rows FILE`` keeps every priced
setting (JSON lines) so that a stopped or larger run resumes from it. ``--store STORE`` prints instead,
per path frame, what a store's frontier for that camera holds (no renders): Max's stored frame rate, the
least error of its real-time points and how many are within the budget.

    .venv/bin/python bench/bench_space_steps.py lab --profile desktop --size 320x180 --threads 1 \\
        --frames 73,438 --neighbourhood 3 --rows lab_space.jsonl
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from addon.core.campaign import parse_size
from addon.core.report import preset_indices
from service.camera_path import CameraPath
from service.display_pricing.tracing import Renderer
from service.evaluation import CameraSpec, _price, image_error, read_scene
from service.optimize import resolve_space
from service.params import ParameterSpace, default_space
from service.store.frame_rate import meets_frame_rate

REPO = Path(__file__).resolve().parent.parent

#: Values outside the default space, as RenderSettings fields (name, fields).
CANDIDATES: tuple[tuple[str, dict[str, Any]], ...] = (
    ("sampling=adaptive_supersample_3x3", {"mode": "supersample", "block": 3}),
    ("sampling=adaptive_supersample_4x4", {"mode": "supersample", "block": 4}),
    ("shadow_samples=8", {"shadow_samples": 8}),
    ("shadow_samples=2", {"shadow_samples": 2}),
    ("ao_samples=12", {"ao_samples": 12}),
    ("ao_samples=2", {"ao_samples": 2}),
    ("resolution_scale=0.95", {"resolution_scale": 0.95}),
)


def built_scene(name: str) -> tuple[Any, CameraPath]:
    """A scene built by ``python -m blend_scenes.build --scene NAME`` and its camera path."""
    d = REPO / "blend_scenes" / "build" / name
    return read_scene(d / "scene.rbscene"), CameraPath.load(d / "path.json")


def cameras(path: CameraPath, n: int, size: tuple[int, int], step: int = 0,
            frames: Sequence[int] = ()) -> list[tuple[int, CameraSpec]]:
    """``n`` path frames spread evenly (the middle of ``n`` equal parts), or with ``step`` every
    ``step``-th frame from the first (the main job's evaluated frames), or the path frames ``frames``."""
    out = []
    numbers = (list(frames) if frames else range(0, len(path), step) if step > 0 else
               [round((k + 0.5) * (len(path) - 1) / n) for k in range(n)])
    for i in numbers:
        if not 0 <= i < len(path):
            raise ValueError(f"path frame {i} is not on the path (0..{len(path) - 1})")
        f = path.frames[i]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        out.append((i, CameraSpec.from_matrix(m, f.vfov, *size)))
    return out


class Pricer:
    """Whole-frame pricing of RenderSettings at a few cameras, Max rendered once per camera."""

    def __init__(self, scene: Any, cams: list[tuple[int, CameraSpec]], profile: str, fps: float,
                 metric: str, threads: int | None, space: ParameterSpace | None = None) -> None:
        self.r = Renderer(scene, threads)
        self.cams, self.profile, self.fps, self.metric = cams, profile, fps, metric
        self.space = space or default_space()
        self.max = self.space.to_settings(self.space.max_quality_indices())
        self.refs = [self.r.frame(c.to_camera(), self.max) for _, c in cams]
        self.seen: dict[tuple, dict[str, Any]] = {}

    def price(self, settings: Any, filtered: bool = False) -> dict[str, Any]:
        """``filtered``: the error after a 3x3 Blackman-Harris pixel filter on the image (what the
        sub-pixel modes' resolve applies, here on one sample a pixel; power unchanged, the filter's own
        cost not counted): how much of a 1-spp mode's error is the missing filter."""
        key = (tuple(sorted(dataclasses.asdict(settings).items())), filtered)
        if key in self.seen:
            return self.seen[key]
        errs, powers, fpss, times, energy, rays = [], [], [], [], {}, {}
        for (_, cam), ref in zip(self.cams, self.refs, strict=True):
            res = ref if settings == self.max else self.r.frame(cam.to_camera(), settings)
            img = _pixel_filter(res.image) if filtered else res.image
            errs.append(0.0 if res is ref else image_error(self.metric, ref.image, img))
            p, frame_time, b = _price(res, self.profile, self.fps)
            powers.append(p)
            fpss.append(b["fps"])
            times.append(frame_time)
            for k, v in b.items():
                if k.startswith("energy_j.") and k != "energy_j.static":
                    energy[k[9:]] = energy.get(k[9:], 0.0) + v / len(self.cams)
            for k in ("rays_primary", "rays_shadow", "rays_ao", "rays_reflection", "rays_refraction"):
                rays[k[5:]] = rays.get(k[5:], 0.0) + res.counters[k] / len(self.cams)
        out = {"errors": errs, "error": float(np.mean(errs)), "power": float(np.mean(powers)),
               "fps": float(np.mean(fpss)), "energy": energy, "rays": rays,
               "powers": powers, "fps_per_camera": fpss, "frame_times": times}
        self.seen[key] = out
        return out


def _pixel_filter(img: np.ndarray) -> np.ndarray:
    """Separable Blackman-Harris filter 1.5 px in radius (Cycles' default, sim_core's resolve) over pixel
    centres: taps at -1, 0, 1 px; edges repeated."""
    def bh(o: float) -> float:
        v = 2.0 * np.pi * (o / 3.0 + 0.5)
        return max(0.0, 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v))
    w = np.array([bh(-1.0), bh(0.0), bh(1.0)])
    w /= w.sum()
    p = np.pad(img, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h = w[0] * p[:, :-2] + w[1] * p[:, 1:-1] + w[2] * p[:, 2:]
    return (w[0] * h[:-2] + w[1] * h[1:-1] + w[2] * h[2:]).astype(np.float32)


# -- the neighbourhood of Max ------------------------------------------------------------------------

#: Sampling modes whose renders read the normal threshold and multi-rate (``RenderSettings.adaptive``).
ADAPTIVE_MODES = ("undersample", "supersample")


def distance(space: ParameterSpace, indices: Sequence[int]) -> int:
    """L1 index distance from the space's maximum quality: steps below Max summed over the parameters."""
    return sum(abs(m - int(i)) for m, i in zip(space.max_quality_indices(), indices, strict=True))


def neighbourhood(space: ParameterSpace, k: int) -> list[tuple[int, ...]]:
    """Every settings vector within distance ``k`` of Max, fixed parameters at their value, nearest
    first (then in index order)."""
    mq = space.max_quality_indices()
    pos = space.free_positions
    out = []
    for free in itertools.product(*(range(len(space.parameters[i].values)) for i in pos)):
        idx = list(mq)
        for i, v in zip(pos, free, strict=True):
            idx[i] = v
        if distance(space, idx) <= k:
            out.append(tuple(idx))
    return sorted(out, key=lambda t: (distance(space, t), t))


def canonical(settings: Any, ref: Any) -> Any:
    """``settings`` with the fields its sampling mode does not read set as in ``ref``: the normal
    threshold and multi-rate act only in the adaptive modes, so under FSAA or 1 spp they render alike."""
    if settings.mode in ADAPTIVE_MODES:
        return settings
    return dataclasses.replace(settings, normal_threshold_deg=ref.normal_threshold_deg,
                               multirate=ref.multirate)


def _settings_key(settings: Any) -> str:
    return json.dumps(sorted(dataclasses.asdict(settings).items()))


def _check_canonical(pr: Pricer) -> None:
    """Render Max with the normal threshold and multi-rate changed at the first camera: the same image and
    counters as Max, or ``canonical`` would merge settings that render differently."""
    if pr.max.mode in ADAPTIVE_MODES:
        return
    cam, ref = pr.cams[0][1], pr.refs[0]
    other = dataclasses.replace(pr.max, normal_threshold_deg=pr.max.normal_threshold_deg + 17.0,
                                multirate=not pr.max.multirate)
    res = pr.r.frame(cam.to_camera(), other)
    if not (np.array_equal(res.image, ref.image) and dict(res.counters) == dict(ref.counters)):
        raise RuntimeError(f"{pr.max.mode} reads the normal threshold or multi-rate: cannot merge settings")


def _changed(space: ParameterSpace, idx: Sequence[int]) -> str:
    mq = space.values_of(space.max_quality_indices())
    vals = space.values_of(idx)
    return ", ".join(f"{k}={v}" for k, v in vals.items() if v != mq[k]) or "Max"


def neighbourhood_table(space: ParameterSpace, rows: list[tuple[tuple[int, ...], dict[str, Any]]],
                        frames: Sequence[int], fps: float, budget: float) -> list[str]:
    """Per path frame: Max's fps and power, how many of ``rows`` keep ``fps``, how many keep ``fps`` with
    error <= ``budget`` (and the nearest distance of one), the cheapest of those, the most accurate one
    that keeps ``fps``. ``rows``: (indices, price) with per-camera lists, Max first."""
    out = [f"| frame | Max: fps, power (W) | settings keeping {fps:g} fps | of them error <= {budget:g} "
           "(nearest distance) | cheapest such: saved vs Max, error, fps, power (W), setting | "
           f"most accurate at {fps:g} fps: error, power (W), setting |",
           "|---|---|---|---|---|---|"]
    mx = next(r for idx, r in rows if distance(space, idx) == 0)
    for j, frame in enumerate(frames):
        rt = [(idx, r) for idx, r in rows if meets_frame_rate(r["frame_times"][j], fps)]
        ok = [(idx, r) for idx, r in rt if r["errors"][j] <= budget]
        cheap = "none"
        if ok:
            idx, r = min(ok, key=lambda t: (t[1]["powers"][j], t[1]["errors"][j]))
            saved = 100.0 * (1.0 - r["powers"][j] / mx["powers"][j])
            cheap = (f"{saved:.1f} %, {r['errors'][j]:.4f}, {r['fps_per_camera'][j]:.1f}, "
                     f"{r['powers'][j]:.2f}, {_changed(space, idx)}")
        best = "none"
        if rt:
            idx, r = min(rt, key=lambda t: (t[1]["errors"][j], t[1]["powers"][j]))
            best = f"{r['errors'][j]:.4f}, {r['powers'][j]:.2f}, {_changed(space, idx)}"
        near = f" ({min(distance(space, idx) for idx, _ in ok)})" if ok else ""
        out.append(f"| {frame} | {mx['fps_per_camera'][j]:.1f}, {mx['powers'][j]:.2f} | {len(rt)} | "
                   f"{len(ok)}{near} | {cheap} | {best} |")
    return out


def run_neighbourhood(pr: Pricer, k: int, budget: float, rows_path: Path | None,
                      header: dict[str, Any]) -> None:
    """Price every setting within distance ``k`` of Max at ``pr``'s cameras, nearest first, and print the
    per-frame table after each whole distance (exact for the distances done)."""
    space = pr.space
    _check_canonical(pr)
    done: dict[str, dict[str, Any]] = {}
    if rows_path is not None and rows_path.exists():
        with rows_path.open() as f:
            lines = [json.loads(line) for line in f if line.strip()]
        if lines and lines[0] != header:
            raise SystemExit(f"{rows_path} holds another run ({lines[0]}); this one is {header}")
        done = {r["key"]: r for r in lines[1:]}
    sink = None
    if rows_path is not None:
        sink = rows_path.open("a")
        if not done and rows_path.stat().st_size == 0:
            sink.write(json.dumps(header) + "\n")
    frames = [i for i, _ in pr.cams]
    todo = neighbourhood(space, k)
    rows: list[tuple[tuple[int, ...], dict[str, Any]]] = []
    t0, c0, renders = time.time(), time.process_time(), 0
    for n, idx in enumerate(todo):
        key = _settings_key(canonical(space.to_settings(idx), pr.max))
        if key not in done:
            r = pr.price(canonical(space.to_settings(idx), pr.max))
            renders += 0 if distance(space, idx) == 0 else len(frames)
            done[key] = {"key": key, "errors": r["errors"], "powers": r["powers"],
                         "fps_per_camera": r["fps_per_camera"], "frame_times": r["frame_times"]}
            if sink is not None:
                sink.write(json.dumps(done[key]) + "\n")
                sink.flush()
        rows.append((idx, done[key]))
        d = distance(space, idx)
        if n + 1 == len(todo) or distance(space, todo[n + 1]) > d:
            unique = len({_settings_key(canonical(space.to_settings(i), pr.max)) for i, _ in rows})
            print(f"\nwithin distance {d} of Max: {len(rows)} settings ({unique} distinct renders a frame); "
                  f"{renders} renders this run, {time.process_time() - c0:.0f} CPU-s, "
                  f"{time.time() - t0:.0f} s", flush=True)
            print("\n".join(neighbourhood_table(space, rows, frames, pr.fps, budget)), flush=True)
    if sink is not None:
        sink.close()


def store_frontiers(store_path: Path, path: CameraPath, frames: Sequence[int], budget: float) -> list[str]:
    """Per path frame, what a store holds for it: the frontier its lookup reads at the frame's camera
    (``ParetoStore.locate``), Max's stored frame rate there, the least error of its real-time points and
    how many of them are within ``budget``."""
    from service.store import pack_indices
    from service.store.pareto import ParetoStore

    store = ParetoStore.from_json(store_path.read_text())
    mq = pack_indices([p.max_quality for p in store.parameters])
    out = [f"| frame | frontier (points) | Max stored: fps | least error at {store.fps:g} fps | "
           f"real-time within {budget:g} |", "|---|---|---|---|---|"]
    for i in frames:
        f = path.frames[i]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        corner, view = store.locate(m[:3, 3], matrix=m, fov=f.vfov)
        fid = int(store.corner_views[corner, view])
        fr = store.frontiers[fid]
        rt = [j for j in range(len(fr.packed)) if fr.frame_time_s is not None
              and meets_frame_rate(float(fr.frame_time_s[j]), store.fps)]
        mx = [j for j in range(len(fr.packed)) if int(fr.packed[j]) == mq]
        mx_fps = f"{1.0 / float(fr.frame_time_s[mx[0]]):.1f}" if mx and fr.frame_time_s is not None else "-"
        least = f"{min(float(fr.error[j]) for j in rt):.4f}" if rt else "-"
        within = sum(float(fr.error[j]) <= budget for j in rt)
        out.append(f"| {i} | {fid} ({len(fr.packed)}) | {mx_fps} | {least} | {within} |")
    return out


def transfer(store_path: Path, scene: Any, path: CameraPath, frames: Sequence[int], size: tuple[int, int],
             fps: float, budget: float, threads: int | None, error_cap: float, slack: float) -> list[str]:
    """Whether what a store priced at one display size holds real time within ``budget`` at another
    (``size``): per path frame, the frontier its lookup reads there (``ParetoStore.locate``); every point
    of it with stored error <= ``error_cap`` whose stored frame time, scaled by the pixel ratio to
    ``size``, is within ``slack`` times the frame-rate deadline, rendered whole at ``size`` and priced
    like the rest of this bench (error against Max at ``size``, on the store's profile and metric). A row
    a candidate, then a line a frame."""
    from service.store import unpack_indices
    from service.store.pareto import ParetoStore

    store = ParetoStore.from_json(store_path.read_text())
    figures = store.meta.get("figures_resolution")
    if not figures:
        raise SystemExit(f"{store_path} records no figures resolution: nothing to scale from")
    ratio = (size[0] * size[1]) / (int(figures[0]) * int(figures[1]))
    space = default_space()
    profile, metric = store.profile, str(store.meta.get("metric", "ssim"))
    out = [f"store {store_path} ({profile}, {metric}, figures at {figures[0]}x{figures[1]}), priced again at "
           f"{size[0]}x{size[1]} (pixel ratio {ratio:g}); candidates: stored error <= {error_cap:g}, "
           f"stored frame time x ratio <= {slack:g} / {fps:g} fps",
           f"| frame | setting (from Max) | stored error | error at {size[0]}x{size[1]} | "
           f"stored fps (flat out) | fps at {size[0]}x{size[1]} (flat out) | frame time ratio | "
           f"power (W) | saved vs Max | {fps:g} fps within {budget:g} |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    summary = []
    for i in frames:
        f = path.frames[i]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        corner, view = store.locate(m[:3, 3], matrix=m, fov=f.vfov)
        fr = store.frontier(corner, view)
        if fr.frame_time_s is None:
            raise SystemExit(f"{store_path} records no frame times")
        picks = [j for j in range(len(fr.packed)) if float(fr.error[j]) <= error_cap
                 and float(fr.frame_time_s[j]) * ratio <= slack / fps]
        cam = cameras(path, 0, size, frames=[i])
        pr = Pricer(scene, cam, profile, fps, metric, threads, space)
        mx = pr.price(pr.max)
        kept = []
        for j in sorted(picks, key=lambda j: float(fr.frame_time_s[j])):
            idx = space.indices_of(store.settings_of(unpack_indices(int(fr.packed[j]), store.n_params)))
            r = pr.price(space.to_settings(idx))
            t = r["frame_times"][0]
            ok = meets_frame_rate(t, fps) and r["error"] <= budget
            if ok:
                kept.append((r["power"], r["error"], _changed(space, idx)))
            saved = 100.0 * (1.0 - r["power"] / mx["power"])
            out.append(f"| {i} | {_changed(space, idx)} | {float(fr.error[j]):.4f} | {r['error']:.4f} | "
                       f"{1.0 / float(fr.frame_time_s[j]):.1f} | {1.0 / t:.1f} | "
                       f"{t / float(fr.frame_time_s[j]):.2f} | {r['power']:.2f} | {saved:.1f} % | "
                       f"{'yes' if ok else 'no'} |")
            print(out[-1], file=sys.stderr, flush=True)  # progress: a 1280x720 row takes a minute
        best = min(kept) if kept else None
        head = f"| {i} | {1.0 / mx['frame_times'][0]:.2f}, {mx['power']:.2f} | {len(picks)} | {len(kept)} | "
        cheapest = (f"{100.0 * (1.0 - best[0] / mx['power']):.1f} %, {best[1]:.4f}, {best[2]}" if best
                    else "none")
        summary.append(f"{head}{cheapest} |")
    return [*out, "", f"| frame | Max at {size[0]}x{size[1]}: fps (flat out), W | candidates | {fps:g} fps "
                      f"within {budget:g} | cheapest such: saved vs Max, error, setting |",
                  "|---|---|---|---|---|", *summary]


def fmt(name: str, r: dict[str, Any], mx: dict[str, Any]) -> str:
    saved = 100.0 * (1.0 - r["power"] / mx["power"])
    top = sorted(r["energy"].items(), key=lambda kv: -kv[1])[:3]
    energy = ", ".join(f"{k} {1000 * v:.0f}" for k, v in top)
    rays = r["rays"]
    kinds = ("primary", "shadow", "ao", "reflection", "refraction")
    ray_s = " / ".join(f"{rays[k] / 1e6:.2f}" for k in kinds)
    errs = r["errors"]
    per_cam = (" ".join(f"{e:.4f}" for e in errs) if len(errs) <= 8 else
               f"max {max(errs):.4f}, {sum(e > 0.02 for e in errs)} of {len(errs)} over 0.02")
    return (f"| {name} | {r['error']:.4f} | {per_cam} | {r['power']:.2f} | {r['fps']:.1f} | {saved:.1f} % | "
            f"{ray_s} | {energy} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--profile", default="desktop")
    ap.add_argument("--size", type=parse_size, default=(320, 180))
    ap.add_argument("--cameras", type=int, default=4)
    ap.add_argument("--frame-step", type=int, default=0,
                    help="every N-th path frame instead of --cameras (the main job: 19 for 1680)")
    ap.add_argument("--frames", type=lambda v: [int(x) for x in v.split(",")], default=[],
                    help="these path frames (comma-separated) instead of --cameras")
    ap.add_argument("--neighbourhood", type=int, default=None, metavar="K",
                    help="only price every setting within index distance K of Max (see above)")
    ap.add_argument("--rows", type=Path, default=None,
                    help="with --neighbourhood: JSON lines of every priced setting, read back to resume")
    ap.add_argument("--store", type=Path, default=None,
                    help="only print what this store's frontiers hold at the path frames (no renders)")
    ap.add_argument("--transfer", type=Path, default=None, metavar="STORE",
                    help="only price at --size what STORE (priced at another size) holds near real time "
                         "within the budget at --frames (see transfer())")
    ap.add_argument("--transfer-error", type=float, default=None,
                    help="with --transfer: stored error cap (default twice --budget)")
    ap.add_argument("--transfer-slack", type=float, default=2.0,
                    help="with --transfer: scaled stored frame time at most this many deadlines")
    ap.add_argument("--no-steps", action="store_true", help="skip the single steps and the Max-Mid preset")
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--metric", default="ssim")
    ap.add_argument("--budget", type=float, default=0.02)
    ap.add_argument("--candidates", action="store_true", help="also price the values outside the space")
    ap.add_argument("--greedy", action="store_true", help="also walk down from Max within --budget")
    ap.add_argument("--extra", nargs="*", default=[],
                    help="further settings as name=FIELD:VALUE,FIELD:VALUE (fields over Max), e.g. "
                         "s4a8=shadow_samples:4,ao_samples:8")
    ap.add_argument("--pixel-filter", action="store_true",
                    help="also each --extra setting's error with a 3x3 Blackman-Harris filter on its image")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    t0 = time.time()
    scene, path = built_scene(args.scene)
    cams = cameras(path, args.cameras, args.size, args.frame_step, args.frames)
    if args.store is not None:
        print("\n".join(store_frontiers(args.store, path, [i for i, _ in cams], args.budget)))
        return
    if args.transfer is not None:
        cap = 2.0 * args.budget if args.transfer_error is None else args.transfer_error
        lines = transfer(args.transfer, scene, path, [i for i, _ in cams], args.size, args.fps, args.budget,
                         args.threads, cap, args.transfer_slack)
        print("\n".join(lines))
        print(f"({time.time() - t0:.0f} s, {time.process_time():.0f} CPU-s)")
        return
    if args.neighbourhood is not None:
        space = resolve_space(scene, default_space(), path, args.threads)
        pr = Pricer(scene, cams, args.profile, args.fps, args.metric, args.threads, space)
        print(f"{args.scene}, {args.size[0]}x{args.size[1]}, profile {args.profile} at {args.fps:g} fps, "
              f"metric {args.metric}, error budget {args.budget:g}; path frames {[i for i, _ in cams]}; "
              f"fixed as inert: {', '.join(space.fixed) or 'none'}; settings within distance "
              f"{args.neighbourhood} of Max: {len(neighbourhood(space, args.neighbourhood))}", flush=True)
        header = {"scene": args.scene, "size": list(args.size), "profile": args.profile, "fps": args.fps,
                  "metric": args.metric, "frames": [i for i, _ in cams], "fixed": dict(space.fixed)}
        run_neighbourhood(pr, args.neighbourhood, args.budget, args.rows, header)
        print(f"({time.time() - t0:.0f} s, {time.process_time():.0f} CPU-s)")
        return
    pr = Pricer(scene, cams, args.profile, args.fps, args.metric, args.threads)
    space = pr.space
    mq = space.max_quality_indices()
    mx = pr.price(pr.max)
    print(f"{args.scene}, {args.size[0]}x{args.size[1]}, profile {args.profile} at {args.fps:g} fps, metric "
          f"{args.metric}; path frames {[i for i, _ in cams]}")
    print("| setting (from Max) | mean error | error per camera | power (W) | fps | saved vs Max | "
          "rays (M): primary / shadow / AO / reflection / refraction | top dynamic energy (mJ/frame) |")
    print("|---|---|---|---|---|---|---|---|")
    print(fmt("Max", mx, mx), flush=True)
    for i, p in enumerate(space.parameters):
        if args.no_steps:
            break
        if mq[i] == 0:
            continue
        idx = list(mq)
        idx[i] = mq[i] - 1
        print(fmt(f"{p.name}={p.values[idx[i]]}", pr.price(space.to_settings(idx)), mx), flush=True)
    counts = [len(p.values) for p in space.parameters]
    mqs = [p.max_quality for p in space.parameters]
    for level, name in () if args.no_steps else ((0.75, "Max-Mid"),):
        idx = preset_indices(counts, mqs, level)
        vals = ", ".join(f"{k}={v}" for k, v in space.values_of(idx).items() if v != space.values_of(mq)[k])
        print(fmt(f"{name} ({vals})", pr.price(space.to_settings(idx)), mx), flush=True)
    if args.candidates:
        for name, fields in CANDIDATES:
            print(fmt(name, pr.price(dataclasses.replace(pr.max, **fields)), mx), flush=True)
    for spec in args.extra:
        name, _, body = spec.partition("=")
        fields: dict[str, Any] = {}
        for kv in body.split(","):
            k, _, v = kv.partition(":")
            fields[k] = _parse_value(v)
        print(fmt(f"{name} ({body})", pr.price(dataclasses.replace(pr.max, **fields)), mx), flush=True)
        if args.pixel_filter:
            filt = pr.price(dataclasses.replace(pr.max, **fields), True)
            print(fmt(f"{name} ({body}), pixel filter", filt, mx), flush=True)
    if args.greedy:
        idx = list(mq)
        cur = mx
        steps = []
        while True:
            best = None
            for i in range(len(space.parameters)):
                if idx[i] == 0:
                    continue
                trial = list(idx)
                trial[i] -= 1
                r = pr.price(space.to_settings(trial))
                if r["error"] <= args.budget and r["power"] < cur["power"] - 1e-6 and (
                        best is None or r["power"] < best[1]["power"]):
                    best = (trial, r, i)
            if best is None:
                break
            idx, cur, i = best
            steps.append(f"{space.parameters[i].name}={space.parameters[i].values[idx[i]]}")
            print(fmt("greedy: " + ", ".join(steps), cur, mx), flush=True)
    print(f"({time.time() - t0:.0f} s)")


def _parse_value(v: str) -> Any:
    for cast in (int, float):
        try:
            return cast(v)
        except ValueError:
            pass
    return {"True": True, "False": False}.get(v, v)


if __name__ == "__main__":
    main()
