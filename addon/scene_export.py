"""The scene as glTF: the one export with the extras sim_core's loader reads, used by the scene generators
(``blend_scenes``: the scene.glb that ``make demo``, the CLI and glTF uploads read). The add-on's own jobs
and previews send the depsgraph translation instead (``ops_optimize.export_scene``)."""

from __future__ import annotations

from pathlib import Path

import bpy


def export_glb(scene: bpy.types.Scene, path: str | Path) -> Path:
    """glTF binary of ``scene``: modifiers applied, lights and cameras included, Y up (glTF's frame), no
    animation (the simulator reads one pose), and custom properties as extras: sim_core's loader reads
    the environment (scene property ``render_budget_environment``) and emitter radii
    (``render_budget_radius`` on light data) from them."""
    path = Path(path)
    window = bpy.context.window
    with bpy.context.temp_override(scene=scene, **({"window": window} if window else {})):
        if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", export_apply=True,
                                  export_lights=True, export_cameras=True, export_yup=True,
                                  export_extras=True, export_animations=False, use_active_scene=True)
    if not path.is_file():
        raise RuntimeError("glTF export produced no file")
    return path
