"""Blender's evaluated scene as the simulator's scene data: the pure half of the depsgraph translator.

The bpy half (``addon/translate.py``) reads the depsgraph into plain values (mesh arrays, instance
matrices, material inputs, light data, world pixels); this module turns them into a
``sim_core.scene_data.SceneData`` and records what could not be carried exactly as :class:`Note`s, which
the render engine's panel and the optimisation job show to the artist.

The native core has no mesh instancing: every instance becomes world-space triangles. Instances of one
evaluated mesh share its corner arrays (read from Blender once) and are only transformed per instance.

The package: :mod:`.notes` (notes and the result), :mod:`.meshes` (corner meshes, instance transforms),
:mod:`.conversions` (material, texture, light and world inputs as the simulator's values) and
:mod:`.assembler` (everything collected, built into one ``SceneData``). sim_core is imported inside
functions: the add-on registers without loading the native core.
"""

from __future__ import annotations

from .assembler import SceneAssembler
from .conversions import (
    DEFAULT_BASE_COLOR,
    ImageData,
    LightInputs,
    MaterialInputs,
    WorldInputs,
    environment_from_inputs,
    environment_map,
    light_from_inputs,
    material_from_inputs,
    srgb_to_linear,
    texture_from_image,
)
from .meshes import Instance, MeshArrays, corner_mesh, transform_mesh
from .notes import Note, Notes, Severity, Translation, notes_text

__all__ = [
    "DEFAULT_BASE_COLOR", "ImageData", "Instance", "LightInputs", "MaterialInputs", "MeshArrays", "Note",
    "Notes", "SceneAssembler", "Severity", "Translation", "WorldInputs", "corner_mesh",
    "environment_from_inputs", "environment_map", "light_from_inputs", "material_from_inputs", "notes_text",
    "srgb_to_linear", "texture_from_image", "transform_mesh",
]
