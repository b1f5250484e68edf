"""Scene file loaders (pure Python + numpy): glTF 2.0 as Blender exports it, and Wavefront OBJ."""

from .gltf import GLTF_TO_BLENDER, load_gltf
from .obj import load_obj

__all__ = ["GLTF_TO_BLENDER", "load_gltf", "load_obj"]
