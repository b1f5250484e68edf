"""Plain scene description handed from the loaders (glTF, OBJ, arrays, Blender's depsgraph) to the core.

Everything here is a dataclass of numbers, strings, tuples and numpy arrays, so a SceneData can be written
to a self-contained file and read back. Validation lives here, at the edge, so the C++ side can trust what
it receives. Units and frames: Blender's (metres, Z up); light intensities radiometric (see Light), with
Light.from_blender converting Blender's watts.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

LightKind = Literal["point", "spot", "sun", "area"]
AreaShape = Literal["square", "rectangle", "disk", "ellipse"]
AlphaMode = Literal["opaque", "clip", "hashed"]
Wrap = Literal["repeat", "clamp", "mirror"]
Colorspace = Literal["srgb", "linear"]

ALPHA_MODES: tuple[str, ...] = ("opaque", "clip", "hashed")
WRAPS: tuple[str, ...] = ("repeat", "clamp", "mirror")
AREA_SHAPES: tuple[str, ...] = ("square", "rectangle", "disk", "ellipse")
#: Largest texture side accepted (the native core allows 65536; this keeps one image under ~1 GiB).
MAX_TEXTURE_SIDE = 16384


def _vec3(value: object, name: str) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (3,):
        raise ValueError(f"{name} must have 3 components, got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def finite_clamped(image: np.ndarray, what: str, *, low: float = 0.0) -> np.ndarray:
    """``image`` as float32 with NaN/-inf and values below ``low`` set to ``low`` and +inf to the largest
    finite value, warning once with the counts (HDRIs often hold tiny negative texels: clamp, never
    reject)."""
    arr = np.asarray(image, dtype=np.float32)
    bad_nan = ~np.isfinite(arr)
    below = np.isfinite(arr) & (arr < low)
    n_nan, n_below = int(np.count_nonzero(bad_nan)), int(np.count_nonzero(below))
    if not (n_nan or n_below):
        return arr
    out = arr.copy()
    finite = out[np.isfinite(out)]
    top = float(finite.max()) if finite.size else low
    out[np.isposinf(out)] = max(top, low)
    out[np.isnan(out) | np.isneginf(out)] = low
    out[below] = low
    warnings.warn(
        f"{what}: clamped {n_below} value(s) below {low} and {n_nan} non-finite value(s)", stacklevel=3
    )
    return out


@dataclass(frozen=True, eq=False)
class Texture:
    """A base-colour image, shared by every material that names its index in ``SceneData.textures``.

    image: (H, W, C) with C in 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA); row 0 at the top. uint8
      images are encoded in ``colorspace`` ("srgb", what 8-bit colour images are, or "linear"); float
      images are linear (negative and non-finite values are clamped with a warning). The core keeps 8-bit
      images as 8 bits (decoded per texel) and float images as float32, each with a mip pyramid.
    wrap_u / wrap_v: "repeat", "clamp" (Blender's EXTEND) or "mirror" outside [0, 1].
    UVs sampling it follow Blender: (0, 0) is the image's bottom-left corner, v points up. A uint8 image is
    kept as a read-only view (not copied); the core copies it when a Scene is built.
    """

    image: np.ndarray
    colorspace: Colorspace = "srgb"
    wrap_u: Wrap = "repeat"
    wrap_v: Wrap = "repeat"
    name: str = ""

    def __post_init__(self) -> None:
        arr = np.asarray(self.image)
        label = f"texture {self.name!r}" if self.name else "texture"
        if arr.ndim == 2:
            arr = arr[:, :, None]
        if arr.ndim != 3 or arr.shape[2] not in (1, 2, 3, 4):
            shape = np.shape(self.image)
            raise ValueError(f"{label}: image must be (H, W) or (H, W, 1|2|3|4), got shape {shape}")
        h, w = arr.shape[:2]
        if not (1 <= h <= MAX_TEXTURE_SIDE and 1 <= w <= MAX_TEXTURE_SIDE):
            raise ValueError(f"{label}: image size {w}x{h} outside 1..{MAX_TEXTURE_SIDE} a side")
        if arr.dtype == np.uint8:
            pass
        elif np.issubdtype(arr.dtype, np.floating):
            arr = finite_clamped(arr, label)
        else:
            raise ValueError(f"{label}: image dtype must be uint8 or float, got {arr.dtype}")
        if self.colorspace not in ("srgb", "linear"):
            raise ValueError(f"{label}: colorspace must be 'srgb' or 'linear', got {self.colorspace!r}")
        for attr in ("wrap_u", "wrap_v"):
            if getattr(self, attr) not in WRAPS:
                raise ValueError(f"{label}: {attr} must be one of {WRAPS}, got {getattr(self, attr)!r}")
        arr = arr.view()  # read-only view: the caller's array keeps its own flags
        arr.setflags(write=False)
        object.__setattr__(self, "image", arr)

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        return int(self.image.shape[0])

    def rgba(self) -> np.ndarray:
        """The image as contiguous (H, W, 4): uint8 stays uint8 (alpha 255 when absent), float -> float32."""
        img = self.image
        c = img.shape[2]
        one = 255 if img.dtype == np.uint8 else 1.0
        if c in (1, 2):
            rgb = np.repeat(img[:, :, :1], 3, axis=2)
            alpha = img[:, :, 1:2] if c == 2 else np.full((*img.shape[:2], 1), one, img.dtype)
        else:
            rgb = img[:, :, :3]
            alpha = img[:, :, 3:4] if c == 4 else np.full((*img.shape[:2], 1), one, img.dtype)
        out = np.concatenate([rgb, alpha], axis=2)
        return np.ascontiguousarray(out, dtype=np.uint8 if img.dtype == np.uint8 else np.float32)


@dataclass(frozen=True)
class Material:
    """Metallic-roughness PBR material as glTF and Blender's Principled BSDF describe it.

    base_color is linear and multiplies the base-colour texture (``base_color_texture``: an index into the
    scene's textures, None for none). alpha multiplies the texture's alpha; alpha_mode says what it does:
    "opaque" (ignored), "clip" (the surface is cut out where alpha < alpha_cutoff, glTF's MASK) or
    "hashed" (a surface of alpha a stops a fraction a of the samples: a stochastic blend, as Cycles
    renders Principled alpha and EEVEE's hashed mode looks).
    """

    base_color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    metallic: float = 0.0
    roughness: float = 0.5
    transmission: float = 0.0
    ior: float = 1.5
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = ""
    alpha: float = 1.0
    alpha_mode: AlphaMode = "opaque"
    alpha_cutoff: float = 0.5
    base_color_texture: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "base_color", _vec3(self.base_color, "base_color"))
        object.__setattr__(self, "emission", _vec3(self.emission, "emission"))
        for attr in ("metallic", "roughness", "transmission", "alpha", "alpha_cutoff"):
            v = float(getattr(self, attr))
            if not (0.0 <= v <= 1.0):
                raise ValueError(f"material {attr} must be in [0, 1], got {v}")
            object.__setattr__(self, attr, v)
        if not (np.isfinite(self.ior) and 1.0 <= self.ior <= 4.0):
            raise ValueError(f"material ior must be in [1, 4], got {self.ior}")
        if self.alpha_mode not in ALPHA_MODES:
            raise ValueError(f"material alpha_mode must be one of {ALPHA_MODES}, got {self.alpha_mode!r}")
        tex = self.base_color_texture
        if tex is not None:
            if isinstance(tex, bool) or not isinstance(tex, int | np.integer) or tex < 0:
                raise ValueError(f"material base_color_texture must be a texture index >= 0 or None"
                                 f", got {tex!r}")
            object.__setattr__(self, "base_color_texture", int(tex))

    @property
    def is_refractive(self) -> bool:
        return self.transmission > 0.0

    @property
    def is_reflective(self) -> bool:
        return self.metallic > 0.0 or self.roughness < 0.5


def _unit(value: object, name: str) -> tuple[float, float, float]:
    d = np.asarray(_vec3(value, name))
    n = float(np.linalg.norm(d))
    if n == 0.0:
        raise ValueError(f"{name} must be non-zero")
    if abs(n - 1.0) <= _UNIT_TOLERANCE:  # already unit: kept bit for bit (a scene file reads back the same)
        return tuple(float(c) for c in d)  # type: ignore[return-value]
    return tuple(float(c) for c in d / n)  # type: ignore[return-value]


_UNIT_TOLERANCE = 1e-12


@dataclass(frozen=True)
class Light:
    """A light in the world frame, in radiometric units (what the shader multiplies):

    - point / spot: ``intensity`` is radiant intensity (W/sr); ``radius`` > 0 makes it a sphere light
      (soft shadows, irradiance I / (d^2 + radius^2) as Cycles' soft falloff);
    - spot: ``spot_angle`` is the cone's half angle, ``spot_blend`` Blender's blend (smooth edge over that
      fraction of the cone, Cycles' smoothstep);
    - sun: ``intensity`` is irradiance (W/m^2) on a surface facing it; ``radius`` its angular radius (rad);
    - area: ``intensity`` is the radiance (W/(m^2 sr)) of its emitting face, a Lambertian one-sided
      emitter of ``shape`` (square, rectangle, disk, ellipse) and ``size`` x ``size_y`` metres (diameters for
      disk / ellipse; square and disk use ``size`` for both) spanned by ``tangent`` (its local X) and
      ``direction`` x ``tangent`` (its local Y), emitting towards ``direction`` (its local -Z).

    ``direction`` is where the light shines (spot, sun, area). ``Light.from_blender`` builds a light from
    Blender's data (watts, sizes, the object's matrix).
    """

    kind: LightKind = "point"
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    radius: float = 0.0
    spot_angle: float = np.pi / 4
    name: str = ""
    spot_blend: float = 0.15
    shape: AreaShape = "square"
    size: float = 0.0
    size_y: float = 0.0
    tangent: tuple[float, float, float] = (1.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.kind not in ("point", "spot", "sun", "area"):
            raise ValueError(f"light kind must be point, spot, sun or area, got {self.kind!r}")
        object.__setattr__(self, "position", _vec3(self.position, "light position"))
        object.__setattr__(self, "direction", _unit(self.direction, "light direction"))
        object.__setattr__(self, "color", _vec3(self.color, "light color"))
        for attr in ("intensity", "radius", "spot_angle", "spot_blend", "size", "size_y"):
            v = float(getattr(self, attr))
            if not np.isfinite(v) or v < 0.0:
                raise ValueError(f"light {attr} must be finite and >= 0, got {v}")
            object.__setattr__(self, attr, v)
        if self.spot_blend > 1.0:
            raise ValueError(f"light spot_blend must be in [0, 1], got {self.spot_blend}")
        if self.shape not in AREA_SHAPES:
            raise ValueError(f"light shape must be one of {AREA_SHAPES}, got {self.shape!r}")
        tangent = np.asarray(_vec3(self.tangent, "light tangent"))
        if self.kind == "area":
            label = f"area light {self.name!r}" if self.name else "area light"
            if self.shape in ("square", "disk"):
                object.__setattr__(self, "size_y", self.size)
            if not (self.size > 0.0 and self.size_y > 0.0):
                raise ValueError(
                    f"{label} has zero size ({self.size} x {self.size_y} m): an area light needs an emitting "
                    "surface; use a point light for a point emitter"
                )
            d = np.asarray(self.direction)
            unit_orthogonal = abs(float(tangent @ d)) <= _UNIT_TOLERANCE and \
                abs(float(np.linalg.norm(tangent)) - 1.0) <= _UNIT_TOLERANCE
            if not unit_orthogonal:  # (a unit tangent already orthogonal is kept bit for bit)
                ortho = tangent - d * float(tangent @ d)
                if float(np.linalg.norm(ortho)) <= 1e-6 * max(float(np.linalg.norm(tangent)), 1e-30):
                    raise ValueError(f"{label}: tangent must be non-zero and not parallel to its direction")
                tangent = ortho / np.linalg.norm(ortho)
        object.__setattr__(self, "tangent", tuple(float(c) for c in tangent))

    @property
    def area(self) -> float:
        """Emitting area in m^2 (area lights; 0 otherwise)."""
        if self.kind != "area":
            return 0.0
        return self.size * self.size_y * (math.pi / 4 if self.shape in ("disk", "ellipse") else 1.0)

    @classmethod
    def from_blender(
        cls,
        kind: str,
        matrix_world: Any,
        energy: float,
        color: Any = (1.0, 1.0, 1.0),
        *,
        shadow_soft_size: float = 0.0,
        spot_size: float = math.pi / 4,
        spot_blend: float = 0.15,
        angle: float = 0.0,
        shape: str = "SQUARE",
        size: float = 0.0,
        size_y: float = 0.0,
        exposure: float = 0.0,
        name: str = "",
    ) -> Light:
        """A light from Blender's light data and object matrix, in Blender's (Cycles') units.

        kind: Blender's light type ("POINT", "SPOT", "SUN", "AREA", any case). energy: watts for point,
        spot and area lights, irradiance (W/m^2) for sun lights ("Strength"), times 2**exposure.
        Conversions (checked against Cycles renders: bench/cycles_light_units.py): point and spot lights
        radiate energy / (4 pi) W/sr (a spot is a point light masked by its cone), a sun gives energy W/m^2,
        an area light is a Lambertian emitter of radiance energy / (pi * area). matrix_world (4x4): lights
        shine down their local -Z; area sizes scale with the object's X / Y scale. spot_size is Blender's
        full cone angle, angle the sun's angular diameter, shadow_soft_size the point/spot radius.
        """
        m = np.asarray(matrix_world, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError(f"matrix_world must be a finite 4x4 matrix, got shape {m.shape}")
        k = str(kind).lower()
        if k not in ("point", "spot", "sun", "area"):
            raise ValueError(f"Blender light type must be POINT, SPOT, SUN or AREA, got {kind!r}")
        for label, v in (("energy", energy), ("exposure", exposure)):
            if not math.isfinite(float(v)):
                raise ValueError(f"light {label} must be finite, got {v}")
        power = float(energy) * 2.0 ** float(exposure)
        if power < 0:
            raise ValueError(f"light energy must be >= 0, got {energy}")
        direction = -m[:3, 2]
        rgb = tuple(np.asarray(color, dtype=np.float64)[:3])
        common: dict[str, Any] = dict(position=tuple(m[:3, 3]), color=rgb, name=name)
        if np.linalg.norm(direction) == 0:
            raise ValueError(f"light {name!r}: matrix_world has a zero Z axis (zero scale)")
        if k == "sun":
            return cls(kind="sun", direction=tuple(direction), intensity=power, radius=0.5 * float(angle),
                       **common)
        if k in ("point", "spot"):
            return cls(
                kind=k,  # type: ignore[arg-type]
                direction=tuple(direction),
                intensity=power / (4.0 * math.pi),
                radius=float(shadow_soft_size),
                spot_angle=0.5 * float(spot_size),
                spot_blend=float(spot_blend),
                **common,
            )
        return cls._area_from_blender(m, power, str(shape).upper(), float(size), float(size_y), common)

    @classmethod
    def _area_from_blender(cls, m: np.ndarray, power: float, blender_shape: str, size: float, size_y: float,
                           common: dict[str, Any]) -> Light:
        """An area light: a Lambertian emitter of radiance power / (pi * area), sized by its scale."""
        name = common["name"]
        shapes = {"SQUARE": "square", "RECTANGLE": "rectangle", "DISK": "disk", "ELLIPSE": "ellipse"}
        if blender_shape not in shapes:
            raise ValueError(f"area light shape must be one of {sorted(shapes)}, got {blender_shape!r}")
        sx, sy = float(np.linalg.norm(m[:3, 0])), float(np.linalg.norm(m[:3, 1]))
        u_size = size * sx
        v_size = (size_y if blender_shape in ("RECTANGLE", "ELLIPSE") else size) * sy
        native_shape = "rectangle" if blender_shape in ("SQUARE", "RECTANGLE") else "ellipse"
        area = u_size * v_size * (math.pi / 4 if native_shape == "ellipse" else 1.0)
        if not area > 0:
            raise ValueError(
                f"area light {name!r} has zero size ({u_size} x {v_size} m after the object's scale): "
                "Blender's size 0 emits from no surface; give it a size or use a point light"
            )
        return cls(
            kind="area",
            direction=tuple(-m[:3, 2]),
            tangent=tuple(m[:3, 0]),
            intensity=power / (math.pi * area),
            shape=native_shape,  # type: ignore[arg-type]
            size=u_size,
            size_y=v_size,
            **common,
        )


@dataclass
class CameraData:
    """A camera found in a scene file, already in the world frame (Blender convention)."""

    matrix_world: np.ndarray  # (4, 4) float64; looks down local -Z, +Y up
    vfov: float  # radians
    aspect: float = 16 / 9
    name: str = ""


@dataclass
class SceneData:
    """Flat arrays and typed lists: everything a scene needs, before the native core builds its BVH.

    ``environment`` is Blender's world: a constant linear RGB or an equirectangular (H, W, 3) float map
    (row 0 at the top, Cycles' Environment Texture mapping), multiplied by ``environment_strength`` and
    turned by ``environment_rotation`` radians about +Z (a Mapping node's Z rotation before the
    Environment Texture). ``uvs`` are per-vertex texture coordinates (Blender's convention, v up) used by
    materials with a ``base_color_texture`` (an index into ``textures``; one image serves many materials).
    """

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
    uvs: np.ndarray | None = None  # (V, 2) float32 texture coordinates
    textures: list[Texture] = field(default_factory=list)
    environment_strength: float = 1.0
    environment_rotation: float = 0.0

