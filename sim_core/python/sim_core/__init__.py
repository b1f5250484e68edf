"""Simulator of a mobile ray-tracing GPU: tracer, adaptive sampling and energy model."""

from . import _core
from ._core import CacheConfig
from .analysis import SceneAnalysis, analyze, inert_parameters
from .camera import Camera
from .energy import EnergyReport, Profile, list_profiles, load_profile, price, price_tiles, sustained_power
from .geometry import smooth_normals
from .image import load_exr
from .render import (
    COUNTER_NAMES,
    RenderResult,
    StereoResult,
    render,
    render_size,
    render_stereo,
    render_tiled,
    render_window,
    window_apron,
)
from .scene import Scene
from .scene_data import CameraData, Light, Material, SceneData, Texture
from .settings import RenderSettings

__version__ = _core.__version__
__all__ = [
    "COUNTER_NAMES",
    "CacheConfig",
    "Camera",
    "CameraData",
    "EnergyReport",
    "Light",
    "Material",
    "Profile",
    "RenderResult",
    "RenderSettings",
    "Scene",
    "SceneAnalysis",
    "SceneData",
    "StereoResult",
    "Texture",
    "__version__",
    "analyze",
    "inert_parameters",
    "list_profiles",
    "load_exr",
    "load_profile",
    "price",
    "price_tiles",
    "render",
    "render_size",
    "render_stereo",
    "render_tiled",
    "render_window",
    "smooth_normals",
    "sustained_power",
    "window_apron",
]
