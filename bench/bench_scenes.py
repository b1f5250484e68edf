"""Test scenes: size, effects and loading cost. Builds the scenes first (cached), then times the glTF
loader (decode + world transforms) and the simulator's scene construction (validation + BVH) on each.

    python bench/bench_scenes.py [--out DIR] [--repeat N]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "blend_scenes" / "build")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from blend_scenes.build import build

    build(None, args.out)
    from sim_core.loaders import load_gltf

    import sim_core

    header = (f"{'scene':8} {'triangles':>10} {'objects':>7} {'meshes':>6} {'mat':>4} {'lights':>6} "
              f"{'frames':>6} {'build s':>7} {'glb MB':>7} {'load_gltf s':>11} {'Scene s':>8}  effects")
    print(header)
    print("-" * len(header))
    for stats_path in sorted(args.out.glob("*/stats.json")):
        s = json.loads(stats_path.read_text())
        glb = stats_path.parent / "scene.glb"
        load = min(_timed(lambda g=glb: load_gltf(g)) for _ in range(args.repeat))
        scene = min(_timed(lambda g=glb: sim_core.Scene.from_gltf(g)) for _ in range(args.repeat))
        mb = glb.stat().st_size / 1e6
        print(f"{s['name']:8} {s['triangles']:>10,} {s['objects']:>7} {s['unique_meshes']:>6} "
              f"{s['materials']:>4} {s['lights']:>6} {s['frames']:>6} {s['build_seconds']:>7.1f} {mb:>7.1f} "
              f"{load:>11.3f} {scene:>8.3f}  {', '.join(s['effects'])}")


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


if __name__ == "__main__":
    main()
