"""Simulator of a mobile ray-tracing GPU: tracer, adaptive sampling and energy model."""

from . import _core
from .scene import Scene, smooth_normals
from .scene_data import CameraData, Light, Material, SceneData

__version__ = _core.__version__
__all__ = ["CameraData", "Light", "Material", "Scene", "SceneData", "__version__", "smooth_normals"]
