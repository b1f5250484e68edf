"""Scene file loaders (pure Python + numpy): glTF 2.0 as Blender exports it, Wavefront OBJ, and the
render-budget scene file (what the add-on's depsgraph translator writes)."""

from .gltf import GLTF_TO_BLENDER, load_gltf
from .obj import load_obj
from .scene_file import is_scene_file, load_scene_file, read_scene_file, write_scene_file

__all__ = ["GLTF_TO_BLENDER", "is_scene_file", "load_gltf", "load_obj", "load_scene_file", "read_scene_file",
           "write_scene_file"]
