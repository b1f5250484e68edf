"""The final render's Power pass: every tile of a frame priced by the energy model. Before, each tile
went through ``sim_core.price`` alone (a Python call per tile, as ``tile_energy`` did); now all tiles
are priced at once (``sim_core.price_tiles``, the same arithmetic on arrays). Both on the same real
render of a blend_scenes scene (the engine's band-by-band ``render_tiled``), with the largest relative
difference between the two; then the pass itself (``power_pass``: tile energies spread over pixels).

Run: .venv/bin/python bench/bench_power_pass.py [--scene chess] [--size 1920x1080] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from sim_core.loaders import load_gltf  # noqa: E402

import sim_core  # noqa: E402
from addon.core.engine_frame import CameraView, power_pass, tile_energy  # noqa: E402
from addon.core.engine_settings import manual_indices, space  # noqa: E402

DEFAULT_SCENES = REPO / "blend_scenes" / "build"
PRESETS = {
    "1 spp, hard shadows": {"sampling": "1spp", "shadow_samples": "1", "ao_samples": "0", "max_depth": "1"},
    "undersample 4x4": {"sampling": "undersample_4x4", "normal_threshold_deg": "20.0", "ao_samples": "4",
                        "shadow_samples": "4"},
}


def one_by_one(tile_stats, prof, fps: float, settings, scene) -> np.ndarray:
    """The previous computation: each tile priced alone through ``sim_core.price``."""
    return np.array([sim_core.price(SimpleNamespace(counters=t["counters"], settings=settings,
                                                    comparator_histogram=t["comparator_histogram"]),
                                    prof, fps, scene=scene).dynamic_energy_j for t in tile_stats])


def best_cpu(repeat: int, fn, *args) -> tuple[object, float]:
    best, value = float("inf"), None
    for _ in range(repeat):
        t0 = time.process_time()
        value = fn(*args)
        best = min(best, time.process_time() - t0)
    return value, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="chess")
    ap.add_argument("--scenes", type=Path, default=DEFAULT_SCENES)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    folder = args.scenes / args.scene
    if not (folder / "scene.glb").exists():
        from blend_scenes.build import build

        build([args.scene], args.scenes)
    scene = sim_core.Scene.from_scene_data(load_gltf(folder / "scene.glb"))
    path = json.loads((folder / "path.json").read_text())["frames"]
    frame = path[len(path) // 2]
    camera = CameraView(frame["matrix_world"], frame["vfov"], w, h).camera()
    prof = sim_core.load_profile("mobile")
    print(f"{args.scene} at {w}x{h}, profile {prof.name}; CPU s, best of {args.repeat}")
    head = f"{'settings':<22}{'tiles':>7}{'one by one s':>14}{'at once s':>11}{'speed-up':>10}" \
           f"{'max rel diff':>14}{'pass s':>8}"
    print(head)
    print("-" * len(head))
    for name, preset in PRESETS.items():
        settings = space().to_settings(manual_indices(preset))
        result = sim_core.render_tiled(scene, camera, settings, cache=prof.cache,
                                       texture_cache=prof.texture_cache)
        tiles = result.tile_stats
        before, t_before = best_cpu(args.repeat, one_by_one, tiles, prof, 24.0, settings, scene)
        after, t_after = best_cpu(args.repeat, tile_energy, tiles, prof, 24.0, settings, scene)
        diff = float(np.max(np.abs(after - before) / np.maximum(np.abs(before), 1e-300)))
        _, t_pass = best_cpu(args.repeat, power_pass, tiles, after, 24.0, result.render_resolution, (w, h))
        print(f"{name:<22}{len(tiles):>7,}{t_before:>14.3f}{t_after:>11.3f}{t_before / t_after:>9.1f}x"
              f"{diff:>14.1e}{t_pass:>8.3f}")


if __name__ == "__main__":
    main()
