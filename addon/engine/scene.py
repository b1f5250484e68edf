"""The scene the engine renders: Blender's evaluated scene as the simulator's ``SceneData``, each
object's pass index (the Object Index pass), and the depsgraph's updates as the engine's scene cache
reads them (:func:`addon.core.engine_scene.needs_translation`).

TEMPORARY: until the depsgraph translator lands, the scene goes through the add-on's glTF export (what
optimisation jobs receive today: modifiers applied, lights and cameras, no textures, no world HDRI).
"""

from __future__ import annotations

import tempfile
from typing import Any

import bpy

from ..core.engine_scene import Update
from ..ops_optimize import export_glb


def translate(depsgraph: bpy.types.Depsgraph) -> tuple[Any, list[float]]:
    """(SceneData, pass index of each scene object) of the depsgraph's scene."""
    from sim_core.loaders import load_gltf

    scene = bpy.data.scenes.get(depsgraph.scene.name) or depsgraph.scene
    with tempfile.TemporaryDirectory(prefix="render-budget-engine-") as tmp:
        data = load_gltf(export_glb(scene, tmp))
    index = []
    for name in data.object_names:
        obj = bpy.data.objects.get(name)
        index.append(float(obj.pass_index) if obj is not None else 0.0)
    return data, index


def updates(depsgraph: bpy.types.Depsgraph) -> list[Update]:
    out = []
    for u in depsgraph.updates:
        idb = u.id
        out.append(Update(idb.id_type, getattr(idb, "type", "") if idb.id_type == "OBJECT" else "",
                          u.is_updated_geometry, u.is_updated_transform, u.is_updated_shading))
    return out
