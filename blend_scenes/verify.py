"""Check built scenes end to end: ``python -m blend_scenes.verify [--scene NAME ...] [--out DIR]``.

For a few frames of each camera path, the object the simulator's tracer hits at each pixel centre
(scene.glb -> sim_core loader -> path.json -> Camera.from_blender) must be the object Blender's own ray
cast hits in scene.blend. Any disagreement points at the frame conversion, camera or export.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from sim_core.loaders import load_gltf

import sim_core

from .build import DEFAULT_OUT, private_blender_user_folder


def pixel_agreement(scene_dir: Path, frame_indices: list[int] | None = None, width: int = 48,
                    height: int = 27) -> list[tuple[int, float]]:
    """(frame index, fraction of pixels whose hit object agrees) for the given or four spread frames."""
    # lazy: bpy only after main() has kept Blender's user configuration out of the home directory
    import bpy
    from mathutils import Vector

    data = load_gltf(scene_dir / "scene.glb")
    scene = sim_core.Scene.from_scene_data(data)
    frames = json.loads((scene_dir / "path.json").read_text())["frames"]
    if frame_indices is None:
        frame_indices = [0, len(frames) // 3, 2 * len(frames) // 3, len(frames) - 1]
    bpy.ops.wm.open_mainfile(filepath=str(scene_dir / "scene.blend"))
    bscene = bpy.context.scene
    out = []
    for index in frame_indices:
        f = frames[index]
        cam = sim_core.Camera.from_blender(np.array(f["matrix_world"]), f["vfov"], width, height)
        ids = sim_core.render(scene, cam, sim_core.RenderSettings(mode="1spp", max_depth=0)).aovs["object_id"]
        bscene.frame_set(bscene.frame_start + index)
        bcam = bscene.camera
        deps = bpy.context.evaluated_depsgraph_get()
        top_right, _bottom_right, bottom_left, top_left = bcam.data.view_frame(scene=bscene)
        rot, origin = bcam.matrix_world.to_3x3(), bcam.matrix_world.translation
        agree = 0
        for i in range(height):
            for j in range(width):
                u, v = (j + 0.5) / width, (i + 0.5) / height
                local = top_left + (top_right - top_left) * u + (bottom_left - top_left) * v
                hit, *_rest, obj, _m = bscene.ray_cast(deps, origin, (rot @ Vector(local)).normalized())
                theirs = obj.name if hit else None
                mine = data.object_names[ids[i, j]] if ids[i, j] >= 0 else None
                agree += theirs == mine
        out.append((index, agree / (width * height)))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m blend_scenes.verify",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--scene", action="append", help="scene to check (repeatable); default: all built")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="build folder (default: %(default)s)")
    args = parser.parse_args(argv)
    private_blender_user_folder()
    names = args.scene or sorted(p.parent.name for p in args.out.glob("*/stats.json"))
    worst = 1.0
    for name in names:
        result = pixel_agreement(args.out / name)
        worst = min([worst, *(a for _, a in result)])
        print(f"{name:8} " + "  ".join(f"frame {i}: {a:.1%}" for i, a in result), flush=True)
    return 0 if worst >= 0.98 else 1


if __name__ == "__main__":
    sys.exit(main())
