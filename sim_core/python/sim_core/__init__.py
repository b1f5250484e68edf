"""Simulator of a mobile ray-tracing GPU: tracer, adaptive sampling and energy model."""

from . import _core
from .camera import Camera
from .energy import *  # noqa: F403  energy model: price, load_profile, list_profiles, analyze, ...
from .render import COUNTER_NAMES, RenderResult, StereoResult, render, render_stereo
from .scene import Scene, smooth_normals
from .scene_data import CameraData, Light, Material, SceneData
from .settings import RenderSettings

__version__ = _core.__version__
__all__ = [
    "COUNTER_NAMES",
    "Camera",
    "CameraData",
    "Light",
    "Material",
    "RenderResult",
    "RenderSettings",
    "Scene",
    "SceneData",
    "StereoResult",
    "__version__",
    "render",
    "render_stereo",
    "smooth_normals",
]
