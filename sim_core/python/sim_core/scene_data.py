"""Plain scene description handed from the loaders (glTF, OBJ, arrays) to the native core.

Validation lives here, at the edge, so the C++ side can trust what it receives.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

LightKind = Literal["point", "spot", "sun"]


def _vec3(value: object, name: str) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (3,):
        raise ValueError(f"{name} must have 3 components, got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass(frozen=True)
class Material:
    """Metallic-roughness PBR material as glTF and Blender's Principled BSDF describe it."""

    base_color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    metallic: float = 0.0
    roughness: float = 0.5
    transmission: float = 0.0
    ior: float = 1.5
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "base_color", _vec3(self.base_color, "base_color"))
        object.__setattr__(self, "emission", _vec3(self.emission, "emission"))
        for attr in ("metallic", "roughness", "transmission"):
            v = float(getattr(self, attr))
            if not (0.0 <= v <= 1.0):
                raise ValueError(f"material {attr} must be in [0, 1], got {v}")
            object.__setattr__(self, attr, v)
        if not (np.isfinite(self.ior) and 1.0 <= self.ior <= 4.0):
            raise ValueError(f"material ior must be in [1, 4], got {self.ior}")

    @property
    def is_refractive(self) -> bool:
        return self.transmission > 0.0

    @property
    def is_reflective(self) -> bool:
        return self.metallic > 0.0 or self.roughness < 0.5


@dataclass(frozen=True)
class Light:
    """Punctual light in the world frame. Intensity is radiant intensity (W/sr) for point and spot
    lights and irradiance (W/m^2) for sun lights; radius > 0 makes shadows soft (metres for point and
    spot lights, the angular radius in radians for sun lights); spot_angle is the cone's half-angle."""

    kind: LightKind = "point"
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    radius: float = 0.0
    spot_angle: float = np.pi / 4
    name: str = ""

    def __post_init__(self) -> None:
        if self.kind not in ("point", "spot", "sun"):
            raise ValueError(f"light kind must be point, spot or sun, got {self.kind!r}")
        object.__setattr__(self, "position", _vec3(self.position, "light position"))
        d = np.asarray(_vec3(self.direction, "light direction"))
        n = float(np.linalg.norm(d))
        if n == 0.0:
            raise ValueError("light direction must be non-zero")
        object.__setattr__(self, "direction", tuple(float(c) for c in d / n))
        object.__setattr__(self, "color", _vec3(self.color, "light color"))
        for attr in ("intensity", "radius", "spot_angle"):
            v = float(getattr(self, attr))
            if not np.isfinite(v) or v < 0.0:
                raise ValueError(f"light {attr} must be finite and >= 0, got {v}")
            object.__setattr__(self, attr, v)


@dataclass
class CameraData:
    """A camera found in a scene file, already in the world frame (Blender convention)."""

    matrix_world: np.ndarray  # (4, 4) float64; looks down local -Z, +Y up
    vfov: float  # radians
    aspect: float = 16 / 9
    name: str = ""


@dataclass
class SceneData:
    """Flat arrays and typed lists: everything a scene needs, before the native core builds its BVH."""

    positions: np.ndarray  # (V, 3) float32
    triangles: np.ndarray  # (T, 3) uint32
    normals: np.ndarray | None = None  # (V, 3) float32 per-vertex shading normals
    material_ids: np.ndarray | None = None  # (T,) uint32 into materials
    object_ids: np.ndarray | None = None  # (T,) uint32
    materials: list[Material] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)
    cameras: list[CameraData] = field(default_factory=list)
    environment: np.ndarray | tuple[float, float, float] | None = None  # constant RGB or (H, W, 3) map
    source: str = ""
    object_names: list[str] = field(default_factory=list)  # indexed by object_ids (mesh instances)
