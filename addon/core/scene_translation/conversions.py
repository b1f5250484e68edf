"""What the bpy side read (material, light and world inputs, image pixels) as the simulator's values:
clamped to the core's ranges, converted through the one conversion of Blender's units, each approximation
recorded as a note. sim_core is imported inside functions: the add-on registers without the native core."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .notes import Notes

if TYPE_CHECKING:
    from sim_core.scene_data import Light, Material, Texture

#: Principled BSDF defaults (Blender 4.x/5.x) for a material without a node tree.
DEFAULT_BASE_COLOR = (0.8, 0.8, 0.8)


@dataclass(frozen=True)
class ImageData:
    """Pixels of a Blender image as the translator read them: (H, W, C) with row 0 at the top.

    uint8 pixels are encoded in ``colorspace`` ("srgb" or "linear"); float pixels are scene-linear.
    """

    name: str
    pixels: np.ndarray
    colorspace: str = "srgb"

    def mean_linear_rgb(self) -> tuple[float, float, float]:
        """The image's mean colour in linear RGB (what a flat approximation of it should show)."""
        px = self.pixels
        rgb = px[..., :3] if px.shape[-1] >= 3 else np.repeat(px[..., :1], 3, axis=-1)
        if px.dtype == np.uint8:
            x = rgb.astype(np.float64) / 255.0
            if self.colorspace == "srgb":
                x = srgb_to_linear(x)
        else:
            x = np.nan_to_num(rgb.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0).clip(min=0.0)
        mean = x.reshape(-1, 3).mean(axis=0) if x.size else np.zeros(3)
        return (float(mean[0]), float(mean[1]), float(mean[2]))


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


@dataclass(frozen=True)
class MaterialInputs:
    """What the bpy side read from a material's node tree (Principled BSDF inputs, already reduced to
    constants where a link could not be followed: the reader adds a note when it approximates).

    base_image: an Image Texture feeding Base Color through the mesh's UVs (None: constant colour), with
    ``wrap`` its extension ("repeat", "clamp", "mirror") and ``image_alpha`` True when the same image's
    Alpha output drives the BSDF's Alpha (cut-outs; the image's alpha is ignored otherwise).
    """

    name: str
    base_color: tuple[float, float, float] = DEFAULT_BASE_COLOR
    base_image: ImageData | None = None
    metallic: float = 0.0
    roughness: float = 0.5
    transmission: float = 0.0
    ior: float = 1.5
    emission_color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    emission_strength: float = 0.0
    alpha: float = 1.0
    wrap: str = "repeat"
    image_alpha: bool = False


def _unit_interval(value: float, what: str, subject: str, notes: Notes) -> float:
    v = float(value)
    if not math.isfinite(v):
        notes.warn(subject, f"{what} is not a finite number; using 0")
        return 0.0
    if v < 0.0 or v > 1.0:
        clamped = min(1.0, max(0.0, v))
        notes.info(subject, f"{what} {v:g} clamped to {clamped:g}")
        return clamped
    return v


def _colour(value: Sequence[float], what: str, subject: str, notes: Notes) -> tuple[float, float, float]:
    rgb = np.asarray(value, dtype=np.float64).reshape(-1)[:3]
    if rgb.shape != (3,) or not np.all(np.isfinite(rgb)):
        notes.warn(subject, f"{what} is not a finite colour; using black")
        return (0.0, 0.0, 0.0)
    if np.any(rgb < 0):
        notes.info(subject, f"negative {what} components clamped to 0")
        rgb = rgb.clip(min=0.0)
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))


def material_from_inputs(inputs: MaterialInputs, notes: Notes, texture: int | None = None) -> Material:
    """A ``sim_core.Material`` from Principled BSDF inputs: values clamped to the core's ranges (with a
    note), emission = colour x strength, alpha below 1 (or from the texture) as Cycles' stochastic alpha
    ("hashed"). ``texture``: the scene index of ``inputs.base_image`` (None: the image, if any, is reduced to
    its mean colour with a note, as for a mesh without UVs)."""
    from sim_core.scene_data import Material  # lazy: the native core loads on first use

    subject = f"material {inputs.name!r}"
    base = _colour(inputs.base_color, "base colour", subject, notes)
    if inputs.base_image is not None and texture is None:
        mean = inputs.base_image.mean_linear_rgb()
        base = (base[0] * mean[0], base[1] * mean[1], base[2] * mean[2])
    ior = float(inputs.ior)
    if not math.isfinite(ior):
        notes.warn(subject, "IOR is not finite; using 1.5")
        ior = 1.5
    elif not 1.0 <= ior <= 4.0:
        clamped = min(4.0, max(1.0, ior))
        notes.info(subject, f"IOR {ior:g} clamped to {clamped:g} (the simulator takes 1..4)")
        ior = clamped
    strength = float(inputs.emission_strength)
    if not math.isfinite(strength) or strength < 0:
        notes.warn(subject, f"emission strength {strength!r} is not a finite non-negative number; using 0")
        strength = 0.0
    emission_color = _colour(inputs.emission_color, "emission colour", subject, notes)
    alpha = _unit_interval(inputs.alpha, "alpha", subject, notes)
    textured_alpha = texture is not None and inputs.image_alpha
    return Material(
        base_color=base,
        metallic=_unit_interval(inputs.metallic, "metallic", subject, notes),
        roughness=_unit_interval(inputs.roughness, "roughness", subject, notes),
        transmission=_unit_interval(inputs.transmission, "transmission", subject, notes),
        ior=ior,
        emission=tuple(c * strength for c in emission_color),  # type: ignore[arg-type]
        name=inputs.name,
        alpha=alpha,
        alpha_mode="hashed" if alpha < 1.0 or textured_alpha else "opaque",
        base_color_texture=texture,
    )


def texture_from_image(image: ImageData, wrap: str, with_alpha: bool) -> Texture:
    """A ``sim_core.Texture`` of a Blender image: its pixels (row 0 at the top), colour space and wrap; the
    alpha channel only when the material reads it (Cycles ignores an image's alpha otherwise)."""
    from sim_core.scene_data import Texture  # lazy: the native core loads on first use

    px = image.pixels
    if px.shape[-1] == 4 and not with_alpha:
        px = px[..., :3]
    elif px.shape[-1] == 2 and not with_alpha:
        px = px[..., :1]
    return Texture(image=np.ascontiguousarray(px), colorspace=image.colorspace, wrap_u=wrap,  # type: ignore[arg-type]
                   wrap_v=wrap, name=image.name)  # type: ignore[arg-type]


@dataclass(frozen=True)
class LightInputs:
    """Blender light data as read from the depsgraph (units as Blender shows them)."""

    name: str
    kind: str  # POINT, SPOT, SUN, AREA
    matrix_world: np.ndarray
    energy: float  # W (point, spot, area) or W/m^2 (sun)
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    shadow_soft_size: float = 0.0
    spot_size: float = math.pi / 4
    spot_blend: float = 0.15
    angle: float = 0.0
    shape: str = "SQUARE"
    size: float = 0.0
    size_y: float = 0.0
    exposure: float = 0.0
    normalize: bool = True  # area lights: False makes ``energy`` the power per m^2 of the emitter


def light_from_inputs(inputs: LightInputs, notes: Notes) -> Light | None:
    """A ``sim_core.Light`` through ``Light.from_blender`` (the one conversion of Blender's units, checked
    against Cycles); None (with a note) for a light that emits nothing or has no emitting surface."""
    from sim_core.scene_data import Light  # lazy: the native core loads on first use

    subject = f"light {inputs.name!r}"
    power = float(inputs.energy) * 2.0 ** float(inputs.exposure)
    if not math.isfinite(power) or power <= 0.0:
        notes.info(subject, "emits nothing (power 0); left out")
        return None
    colour = _colour(inputs.color, "colour", subject, notes)
    try:
        light = Light.from_blender(
            inputs.kind, inputs.matrix_world, float(inputs.energy), colour,
            shadow_soft_size=max(0.0, float(inputs.shadow_soft_size)), spot_size=float(inputs.spot_size),
            spot_blend=min(1.0, max(0.0, float(inputs.spot_blend))), angle=max(0.0, float(inputs.angle)),
            shape=inputs.shape, size=float(inputs.size), size_y=float(inputs.size_y),
            exposure=float(inputs.exposure), name=inputs.name)
    except ValueError as exc:
        notes.warn(subject, f"left out: {exc}")
        return None
    if light.kind == "area" and not inputs.normalize:
        # Cycles without "Normalize": the power scales with the emitter's area (after the object's scale)
        light = dataclasses.replace(light, intensity=light.intensity * light.area)
    return light


def environment_map(pixels: np.ndarray, name: str, notes: Notes) -> np.ndarray:
    """An equirectangular world image as the core takes it: (H, W, 3) float32 linear RGB, row 0 at the
    zenith; negative and non-finite texels are clamped (with a note), never rejected."""
    from sim_core.scene_data import finite_clamped  # lazy: the native core loads on first use

    px = np.asarray(pixels)
    rgb = px[..., :3] if px.shape[-1] >= 3 else np.repeat(px[..., :1], 3, axis=-1)
    rgb = rgb.astype(np.float32)
    finite = np.isfinite(rgb)
    negative, bad = int(np.count_nonzero(finite & (rgb < 0))), int(np.count_nonzero(~finite))
    if negative or bad:
        notes.warn(f"world image {name!r}", f"clamped {negative} negative and {bad} non-finite texel "
                                             "value(s) to 0 (or the largest finite value for +inf)")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the note says it
            rgb = finite_clamped(rgb, name)
    return np.ascontiguousarray(rgb)


@dataclass(frozen=True)
class WorldInputs:
    """The world as read from its node tree: a constant colour or an equirectangular image, times
    strength, turned by ``rotation_z`` radians about +Z (a Mapping node before the Environment Texture)."""

    color: tuple[float, float, float] = (0.050876, 0.050876, 0.050876)
    image: ImageData | None = None
    strength: float = 1.0
    rotation_z: float = 0.0


def environment_from_inputs(world: WorldInputs, notes: Notes
                            ) -> tuple[np.ndarray | tuple[float, float, float], float, float]:
    """(environment, strength, rotation) for ``SceneData``: a constant colour or the clamped map."""
    strength = float(world.strength)
    if not math.isfinite(strength) or strength < 0:
        notes.warn("world", f"background strength {strength!r} is not a finite non-negative number; using 1")
        strength = 1.0
    rotation = float(world.rotation_z) if math.isfinite(float(world.rotation_z)) else 0.0
    if world.image is None:
        return _colour(world.color, "background colour", "world", notes), strength, 0.0
    return environment_map(world.image.pixels, world.image.name, notes), strength, rotation
