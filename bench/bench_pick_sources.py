"""Where a store's error prediction for a frame goes wrong: at the camera its frontier was priced at (the
display pricing's own error) or between that camera and the frame (the frame sees something else).

For each path frame, the store's pick under the error budget (frame rate first, as the main job looks it
up) is rendered whole at the display size at the frame itself and at the sample camera of the frontier it
came from, against Max at the same camera (``service.evaluation.evaluate``, what verify measures). The
table sets the store's prediction against both:

- ``at sample - stored``: the pricing's error at its own camera (0 for whole-frame pricing, the
  estimate's error for the tile estimator; with guard frames the stored figure is the worst over the
  pricing cameras, so this is then a bound's slack);
- ``frame - at sample``: what the frame adds by not being the camera it was priced at.

    .venv/bin/python bench/bench_pick_sources.py valley out/valley360both/store.json --size 640x360 \\
        --frames 552,690

``--try`` also prices given settings whole at each frame's sample camera: whether the space holds what the
store lacks there.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from addon.core.campaign import parse_size
from bench.bench_space_steps import built_scene
from service.evaluation import CameraSpec, evaluate
from service.params import parse_space_argument, stored_space
from service.store import ParetoStore


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("store", type=Path)
    ap.add_argument("--size", type=parse_size, default=(640, 360))
    ap.add_argument("--frames", type=lambda v: [int(x) for x in v.split(",")], required=True)
    ap.add_argument("--budget", type=float, default=0.02)
    ap.add_argument("--try", dest="tries", nargs="*", default=[], metavar="NAME:VALUE,...",
                    help="settings (changes from Max) also priced whole at each frame's sample camera, "
                         "e.g. sampling:fsaa_2x2,shadow_samples:1,ao_samples:4")
    ap.add_argument("--scaled-to", type=parse_size, default=None, metavar="WxH",
                    help="price power and frame time for this many pixels (what the search does with its "
                         "small images: --size 64x36 --scaled-to 640x360)")
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    target = None if args.scaled_to is None else args.scaled_to[0] * args.scaled_to[1]
    t0 = time.time()
    scene, path = built_scene(args.scene)
    store = ParetoStore.from_json(args.store.read_text())
    space = stored_space(store.parameters)
    max_settings = store.settings_of([p.max_quality for p in store.parameters])
    best = space.indices_of(max_settings)
    w, h = args.size
    pricing = store.meta.get("display_pricing", "?")
    print(f"{args.scene}, store {args.store.name} ({pricing}), whole frames at {w}x{h}, "
          f"`{store.profile}` at {store.fps:g} fps, error budget {args.budget:g}")
    print("| frame | pick | stored (predicted) | whole at sample camera | whole at frame "
          "| at sample - stored | frame - at sample |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    tried_at = []
    for number in args.frames:
        f = path.frames[number]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        hit = store.lookup(f.position, matrix=m, fov=f.vfov, aspect=f.aspect, error_budget=args.budget)
        idx = space.indices_of(hit.settings)
        eye, fwd, up = store.sample_camera(hit.corner, hit.view)
        at_sample = CameraSpec(tuple(eye), tuple(fwd), tuple(up), store.vfov, w, h)
        at_frame = CameraSpec.from_matrix(m, f.vfov, w, h)
        tried_at.append((number, at_sample))
        e_sample, e_frame = (evaluate(scene, cam, idx, space, profile=store.profile, fps=store.fps,
                                      threads=args.threads, reference_indices=best,
                                      target_pixels=target).error for cam in (at_sample, at_frame))
        pick = ", ".join(f"{k}={v}" for k, v in hit.settings.items() if v != max_settings[k])
        rows.append((e_sample - hit.expected_error, e_frame - e_sample))
        print(f"| {number} | {pick or 'Max'} | {hit.expected_error:.4f} | {e_sample:.4f} | {e_frame:.4f} | "
              f"{e_sample - hit.expected_error:+.4f} | {e_frame - e_sample:+.4f} |", flush=True)
    if args.tries:
        print("\n| frame | setting tried at the sample camera | error | power W | fps |")
        print("|---|---|---|---|---|")
    for number, cam in tried_at:
        for text in args.tries:
            ev = evaluate(scene, cam, space.indices_of(_over(max_settings, text)), space,
                          profile=store.profile, fps=store.fps, threads=args.threads, reference_indices=best,
                          target_pixels=target)
            print(f"| {number} | {text} | {ev.error:.4f} | {ev.power_w:.2f} | {1.0 / ev.frame_time_s:.1f} |",
                  flush=True)
    d = np.asarray(rows)
    print(f"\nmean |at sample - stored| {np.mean(np.abs(d[:, 0])):.4f} (mean {np.mean(d[:, 0]):+.4f}); "
          f"mean |frame - at sample| {np.mean(np.abs(d[:, 1])):.4f} (mean {np.mean(d[:, 1]):+.4f}); "
          f"{time.time() - t0:.0f} s")


def _over(base: dict, text: str) -> dict:
    """``base`` with the ``name:value`` changes of ``text``, each value read as ``--space`` reads it."""
    out = dict(base)
    for item in text.split(","):
        name, _, value = item.partition(":")
        try:
            _, (out[name],) = parse_space_argument(f"{name}={value}")
        except ValueError as exc:
            raise SystemExit(str(exc)) from None
    return out


if __name__ == "__main__":
    main()
