"""Which parameters make a fixed preset's error: one preset of a store, with one group of parameters
swapped at a time, rendered at a path frame at several sizes and measured as the main job measures it
(1 - SSIM after the display transform against the store's maximum quality, power on the store's profile).

Written for the valley at 1280x720, where Min's mean error fell below Mid-Min's (above it at 640x360):
the table shows which of the preset's values carry its error, and how that changes with the size.

    .venv/bin/python bench/bench_preset_swaps.py out/valley720g980/store.json --scene valley \
        --preset mid_min --frames 0 --sizes 640x360 1280x720 \
        --swap "no shadow or AO rays:shadow_samples=0,ao_samples=0" ...
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from addon.core.campaign import parse_size
from addon.core.evaluate_path import preset_settings
from blend_scenes.build import DEFAULT_OUT
from service.camera_path import CameraPath
from service.evaluation import CameraSpec, evaluate, read_scene
from service.params import parse_space_argument, stored_space
from service.store import ParetoStore


def swap(text: str) -> tuple[str, dict[str, object]]:
    """``LABEL:NAME=VALUE,NAME=VALUE`` as a label and the values it sets."""
    label, sep, rest = text.partition(":")
    if not sep or not rest:
        raise argparse.ArgumentTypeError(f"expected LABEL:NAME=VALUE[,NAME=VALUE], got {text!r}")
    values = {}
    for item in rest.split(","):
        try:
            name, (value,) = parse_space_argument(item)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from exc
        values[name] = value
    return label, values


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("store", type=Path)
    ap.add_argument("--scene", required=True, help="a blend_scenes scene, already built")
    ap.add_argument("--preset", default="mid_min", choices=("max_mid", "mid_min", "min"))
    ap.add_argument("--frames", type=int, nargs="+", default=[0])
    ap.add_argument("--sizes", type=parse_size, nargs="+", default=[(640, 360), (1280, 720)])
    ap.add_argument("--swap", type=swap, action="append", default=[], metavar="LABEL:NAME=VALUE,...")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()

    store = ParetoStore.from_json(args.store.read_bytes())
    space = stored_space(store.parameters)
    best = space.indices_of(store.settings_of([p.max_quality for p in store.parameters]))
    presets = preset_settings(store)
    base = presets[args.preset]
    variants = {args.preset: base, **{label: {**base, **values} for label, values in args.swap}}
    scene_dir = Path(DEFAULT_OUT) / args.scene
    scene = read_scene(scene_dir / "scene.rbscene")
    path = CameraPath.load(scene_dir / "path.json")
    print(f"{args.preset}: " + ", ".join(f"{k}={v}" for k, v in base.items()))
    print(f"store profile {store.profile}, error = 1 - SSIM against the store's maximum quality\n")
    sizes = [f"{w}x{h}" for w, h in args.sizes]
    print("| frame | settings | " + " | ".join(f"error {s} | power {s} (W)" for s in sizes) + " |")
    print("|---|---|" + "---|---|" * len(sizes))
    for number in args.frames:
        f = path.frames[number]
        m = np.asarray(f.matrix_world, dtype=np.float64)
        cams = [CameraSpec.from_matrix(m, f.vfov, w, h) for w, h in args.sizes]
        for label, settings in variants.items():
            cells = []
            for cam in cams:
                ev = evaluate(scene, cam, space.indices_of(settings), space, profile=store.profile,
                              fps=path.fps, metric="ssim", threads=args.threads, reference_indices=best)
                cells += [f"{ev.error:.4f}", f"{ev.power_w:.1f}"]
            print(f"| {number} | {label} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
