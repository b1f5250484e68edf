"""Blender's evaluated scene as the simulator's scene data: the pure half of the depsgraph translator.

The bpy half (``addon/translate.py``) reads the depsgraph into plain values (mesh arrays, instance
matrices, material inputs, light data, world pixels); this module turns them into a
``sim_core.scene_data.SceneData`` and records what could not be carried exactly as :class:`Note`s, which
the render engine's panel and the optimisation job show to the artist.

The native core has no mesh instancing: every instance becomes world-space triangles. Instances of one
evaluated mesh share its corner arrays (read from Blender once) and are only transformed per instance.
sim_core is imported inside functions: the add-on registers without loading the native core.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

if TYPE_CHECKING:
    from sim_core.scene_data import (
        Light,
        Material,
        SceneData,
        Texture,
    )

Severity = Literal["info", "warning"]

#: Principled BSDF defaults (Blender 4.x/5.x) for a material without a node tree.
DEFAULT_BASE_COLOR = (0.8, 0.8, 0.8)


@dataclass(frozen=True)
class Note:
    """Something the simulated scene does differently from Blender's render, in words for the artist."""

    severity: Severity
    subject: str  # what it is about: "material 'Glass'", "light 'Area'", "world", "object 'Cube'"
    message: str

    def __str__(self) -> str:
        return f"{self.subject}: {self.message}"

    def to_dict(self) -> dict[str, str]:
        return {"severity": self.severity, "subject": self.subject, "message": self.message}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Note:
        sev = str(d.get("severity", "info"))
        if sev not in ("info", "warning"):
            raise ValueError(f"note severity must be 'info' or 'warning', got {sev!r}")
        return cls(sev, str(d.get("subject", "")), str(d.get("message", "")))  # type: ignore[arg-type]


class Notes:
    """An ordered set of notes: the same remark about the same thing is kept once."""

    def __init__(self) -> None:
        self._items: dict[tuple[str, str, str], Note] = {}

    def add(self, severity: Severity, subject: str, message: str) -> None:
        note = Note(severity, subject, message)
        self._items.setdefault((note.severity, note.subject, note.message), note)

    def info(self, subject: str, message: str) -> None:
        self.add("info", subject, message)

    def warn(self, subject: str, message: str) -> None:
        self.add("warning", subject, message)

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self._items.values())

    def __len__(self) -> int:
        return len(self._items)

    def as_list(self) -> list[Note]:
        return list(self._items.values())


def notes_text(notes: Sequence[Note], limit: int = 8) -> str:
    """A short multi-line summary for a panel or a job status (warnings first)."""
    ordered = sorted(notes, key=lambda n: n.severity != "warning")
    lines = [str(n) for n in ordered[:limit]]
    if len(ordered) > limit:
        lines.append(f"... and {len(ordered) - limit} more")
    return "\n".join(lines)


@dataclass
class Translation:
    """The translator's result: scene data ready for ``sim_core.Scene.from_scene_data`` plus notes.

    ``stats``: counts of what was read (objects, instances, unique meshes, triangles, lights, ...) and
    ``seconds`` spent; ``frame`` the scene frame the depsgraph was evaluated at. ``pass_indices``: each
    object's (instance's) Object Index pass value, indexed like ``scene_data.object_names``.
    """

    scene_data: SceneData
    notes: list[Note] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)
    pass_indices: list[int] = field(default_factory=list)  # Blender's Object Index, by object id

    @property
    def warnings(self) -> list[Note]:
        return [n for n in self.notes if n.severity == "warning"]

    def notes_text(self, limit: int = 8) -> str:
        return notes_text(self.notes, limit)


# -- meshes --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MeshArrays:
    """One evaluated mesh in its object's local frame, welded per distinct (vertex, normal, uv) corner.

    positions/normals (N, 3) float32, uvs (N, 2) float32 or None, triangles (T, 3) uint32 indices into
    them, slots (T,) int32 material slot of each triangle (the object's slot list maps it to a material).
    """

    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray | None
    triangles: np.ndarray
    slots: np.ndarray

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])


def corner_mesh(
    vertex_positions: np.ndarray,
    corner_vertices: np.ndarray,
    corner_normals: np.ndarray,
    triangle_corners: np.ndarray,
    triangle_slots: np.ndarray,
    corner_uvs: np.ndarray | None = None,
) -> MeshArrays:
    """Blender's per-corner mesh (loops) as per-vertex arrays the core takes.

    vertex_positions (V, 3); corner_vertices (L,) the vertex of each corner (loop); corner_normals (L, 3)
    Blender's split normals (smooth, flat and sharp edges already resolved); triangle_corners (T, 3) the
    corners of each loop triangle; triangle_slots (T,) material slot indices; corner_uvs (L, 2) or None.
    Corners with the same vertex, normal and UV become one vertex, so smooth meshes keep their sharing and
    flat faces and UV seams get their own vertices.
    """
    co = np.asarray(vertex_positions, dtype=np.float32).reshape(-1, 3)
    cv = np.asarray(corner_vertices, dtype=np.int64).reshape(-1)
    cn = np.asarray(corner_normals, dtype=np.float32).reshape(-1, 3)
    tc = np.asarray(triangle_corners, dtype=np.int64).reshape(-1, 3)
    slots = np.asarray(triangle_slots, dtype=np.int32).reshape(-1)
    if cn.shape[0] != cv.shape[0]:
        raise ValueError(f"corner normals ({cn.shape[0]}) and corners ({cv.shape[0]}) differ in number")
    if slots.shape[0] != tc.shape[0]:
        raise ValueError(f"triangle slots ({slots.shape[0]}) and triangles ({tc.shape[0]}) differ in number")
    if cv.size and (cv.min() < 0 or cv.max() >= co.shape[0]):
        raise ValueError("a corner references a vertex out of range")
    if tc.size and (tc.min() < 0 or tc.max() >= cv.shape[0]):
        raise ValueError("a triangle references a corner out of range")
    uv = None
    if corner_uvs is not None:
        uv = np.asarray(corner_uvs, dtype=np.float32).reshape(-1, 2)
        if uv.shape[0] != cv.shape[0]:
            raise ValueError(f"corner uvs ({uv.shape[0]}) and corners ({cv.shape[0]}) differ in number")
    if tc.shape[0] == 0:
        empty3 = np.zeros((0, 3), np.float32)
        return MeshArrays(empty3, empty3, None if uv is None else np.zeros((0, 2), np.float32),
                          np.zeros((0, 3), np.uint32), slots)
    # one key per corner: vertex index and the exact bits of its normal (and uv)
    parts = [cv.astype(np.int32).view(np.uint8).reshape(-1, 4), np.ascontiguousarray(cn).view(np.uint8)]
    if uv is not None:
        parts.append(np.ascontiguousarray(uv).view(np.uint8))
    keys = np.ascontiguousarray(np.concatenate(parts, axis=1))
    keys = keys.view(np.dtype((np.void, keys.shape[1]))).reshape(-1)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    positions = co[cv[first]]
    normals = cn[first]
    return MeshArrays(
        positions=np.ascontiguousarray(positions),
        normals=np.ascontiguousarray(normals),
        uvs=None if uv is None else np.ascontiguousarray(uv[first]),
        triangles=np.ascontiguousarray(inverse.reshape(-1)[tc], dtype=np.uint32),
        slots=slots,
    )


def transform_mesh(mesh: MeshArrays, matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space (positions, normals, triangles) of one instance of ``mesh``.

    Normals go through the inverse transpose and are renormalised; a mirroring matrix (negative
    determinant) reverses the triangles' winding so their geometric normals still face outwards.
    Raises ValueError for a singular or non-finite matrix (a zero scale).
    """
    m = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
    if not np.all(np.isfinite(m)):
        raise ValueError("instance matrix is not finite")
    linear = m[:3, :3]
    det = float(np.linalg.det(linear))
    if not math.isfinite(det) or abs(det) < 1e-18:
        raise ValueError("instance matrix is singular (zero scale)")
    positions = mesh.positions.astype(np.float64) @ linear.T + m[:3, 3]
    normal_matrix = np.linalg.inv(linear).T
    normals = mesh.normals.astype(np.float64) @ normal_matrix.T
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    triangles = mesh.triangles if det > 0 else mesh.triangles[:, [0, 2, 1]]
    return positions.astype(np.float32), normals.astype(np.float32), triangles


@dataclass(frozen=True)
class Instance:
    """One rendered copy of a mesh: its world matrix, the scene material of each of its slots, a name."""

    mesh_key: Any
    matrix: np.ndarray
    slot_materials: tuple[int, ...]
    name: str
    pass_index: int = 0


# -- materials -----------------------------------------------------------------------------------------
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


# -- lights --------------------------------------------------------------------------------------------
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


# -- world ---------------------------------------------------------------------------------------------
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


# -- assembly ------------------------------------------------------------------------------------------
class SceneAssembler:
    """Collects meshes (once each), instances, materials, lights, world and camera; builds SceneData."""

    def __init__(self) -> None:
        self.notes = Notes()
        self.meshes: dict[Any, MeshArrays] = {}
        self.instances: list[Instance] = []
        self.materials: list[Material] = []
        self._material_index: dict[Any, int] = {}
        self.lights: list[Light] = []
        self.textures: list[Texture] = []
        self._texture_index: dict[Any, int] = {}
        self._inputs: dict[Any, MaterialInputs] = {}
        self.environment: np.ndarray | tuple[float, float, float] | None = None
        self.environment_strength = 1.0
        self.environment_rotation = 0.0
        self.cameras: list[Any] = []
        self.pass_indices: list[int] = []  # of the built scene's objects (after build)

    def material_index(self, key: Any, make: Any) -> int:
        """The scene index of the material known by ``key`` (``make()`` builds it the first time)."""
        idx = self._material_index.get(key)
        if idx is None:
            idx = len(self.materials)
            self.materials.append(make())
            self._material_index[key] = idx
        return idx

    def principled_index(self, key: Any, read: Callable[[], MaterialInputs], *, uvs: bool) -> int:
        """The scene index of a node material (inputs from ``read()``, called once per key). A base-colour
        image becomes a shared texture on meshes with UVs; on a mesh without UVs the material's variant
        shows the image's mean colour (noted)."""
        inputs = self._inputs.get(key)
        if inputs is None:
            inputs = self._inputs[key] = read()
        textured = inputs.base_image is not None and uvs

        def make() -> Material:
            subject = f"material {inputs.name!r}"
            texture = None
            if textured:
                try:
                    texture = self.texture_index(inputs)
                except ValueError as exc:
                    self.notes.warn(subject, f"image texture shows its mean colour: {exc}")
            elif inputs.base_image is not None:
                self.notes.warn(subject, f"image texture {inputs.base_image.name!r} on a mesh without a UV "
                                         "map: shows its mean colour")
            return material_from_inputs(inputs, self.notes, texture)

        return self.material_index((key, textured), make)

    def texture_index(self, inputs: MaterialInputs) -> int:
        image = inputs.base_image
        assert image is not None
        key = (image.name, inputs.wrap, inputs.image_alpha)
        idx = self._texture_index.get(key)
        if idx is None:
            texture = texture_from_image(image, inputs.wrap, inputs.image_alpha)
            idx = self._texture_index[key] = len(self.textures)
            self.textures.append(texture)
        return idx

    def default_material(self) -> int:
        from sim_core.scene_data import Material  # lazy: the native core loads on first use

        return self.material_index(("<default>",), lambda: Material(base_color=DEFAULT_BASE_COLOR,
                                                                     roughness=0.5, name="default"))

    def add_mesh(self, key: Any, mesh: MeshArrays) -> None:
        self.meshes[key] = mesh

    def add_instance(self, mesh_key: Any, matrix: Any, slot_materials: Sequence[int], name: str,
                     pass_index: int = 0) -> None:
        if mesh_key not in self.meshes:
            raise KeyError(f"mesh {mesh_key!r} was not added")
        self.instances.append(Instance(mesh_key, np.asarray(matrix, dtype=np.float64).reshape(4, 4),
                                       tuple(int(i) for i in slot_materials), name, int(pass_index)))

    def add_light(self, light: Light | None) -> None:
        if light is not None:
            self.lights.append(light)

    def build(self, source: str = "") -> SceneData:
        """World-space arrays of every instance (one object id each, in instance order)."""
        from sim_core.scene_data import SceneData  # lazy: the native core loads on first use

        positions, normals, uvs, triangles, material_ids, object_ids, names = [], [], [], [], [], [], []
        pass_indices: list[int] = []
        offset = 0
        for inst in self.instances:
            mesh = self.meshes[inst.mesh_key]
            if mesh.triangle_count == 0:
                continue
            try:
                p, n, t = transform_mesh(mesh, inst.matrix)
            except ValueError as exc:
                self.notes.warn(f"object {inst.name!r}", f"{exc}; left out")
                continue
            table = np.asarray(inst.slot_materials or (self.default_material(),), dtype=np.uint32)
            slots = np.clip(mesh.slots, 0, len(table) - 1)
            positions.append(p)
            normals.append(n)
            uvs.append(mesh.uvs if mesh.uvs is not None else np.zeros((p.shape[0], 2), np.float32))
            triangles.append(t.astype(np.int64) + offset)
            material_ids.append(table[slots])
            object_ids.append(np.full(t.shape[0], len(names), dtype=np.uint32))
            names.append(inst.name)
            pass_indices.append(inst.pass_index)
            offset += p.shape[0]
        if not names:
            raise ValueError("nothing to render: the scene has no visible geometry for rendering")
        self.pass_indices = pass_indices
        if len(self.lights) > 32:
            kept = sorted(self.lights, key=lambda lt: -lt.intensity)[:32]
            self.notes.warn("lights", f"{len(self.lights)} lights, the simulator takes 32: kept the 32 "
                                      "strongest")
            self.lights = kept
        return SceneData(
            positions=np.concatenate(positions).astype(np.float32),
            triangles=np.concatenate(triangles).astype(np.uint32),
            normals=np.concatenate(normals).astype(np.float32),
            material_ids=np.concatenate(material_ids).astype(np.uint32),
            object_ids=np.concatenate(object_ids).astype(np.uint32),
            materials=list(self.materials) or [self._fallback_material()],
            lights=list(self.lights),
            cameras=list(self.cameras),
            environment=self.environment,
            environment_strength=self.environment_strength,
            environment_rotation=self.environment_rotation,
            source=source,
            object_names=names,
            uvs=np.concatenate(uvs).astype(np.float32) if self.textures else None,
            textures=list(self.textures),
        )

    def _fallback_material(self) -> Material:
        from sim_core.scene_data import Material  # lazy: the native core loads on first use

        return Material(name="default")
