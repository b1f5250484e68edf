"""Scenes for the native tracer: validated arrays in, a BVH-backed native scene out.

Every array is checked here (dtype, shape, finite values, index ranges) before it crosses into C++, so a
bad file gives a clear ValueError instead of a crash or a silently wrong image.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from . import _core
from .loaders import load_gltf, load_obj
from .loaders.scene_file import Limits, load_scene_file
from .scene_data import ALPHA_MODES, WRAPS, CameraData, Light, Material, SceneData, Texture, finite_clamped

# Blender's default world colour: what a scene without an environment sees.
DEFAULT_ENVIRONMENT = (0.050876, 0.050876, 0.050876)
_LIGHT_KINDS = {"point": 0, "spot": 1, "sun": 2, "area": 3}
_MATERIAL_FIELDS = 14
_LIGHT_FIELDS = 20


def _as_array(value: Any, name: str, dtype: type, ncols: int | None) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except Exception as exc:  # pragma: no cover - numpy raises many types
        raise ValueError(f"{name} is not array-like: {exc}") from None
    if arr.dtype == object:
        raise ValueError(f"{name} must be numeric, got object array")
    if ncols is None:
        if arr.ndim != 1:
            raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    elif arr.ndim != 2 or arr.shape[1] != ncols:
        raise ValueError(f"{name} must have shape (N, {ncols}), got {arr.shape}")
    if np.issubdtype(dtype, np.integer):
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            if not np.issubdtype(arr.dtype, np.floating) or not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} must hold integers")
            if not np.all(arr == np.round(arr)):
                raise ValueError(f"{name} must hold integers")
        if arr.size and arr.min() < 0:
            raise ValueError(f"{name} must be non-negative, got {int(arr.min())}")
    elif arr.size and not np.all(np.isfinite(arr.astype(np.float64))):
        bad = np.argwhere(~np.isfinite(arr.astype(np.float64)))[0]
        raise ValueError(f"{name} must be finite (NaN/Inf at index {tuple(int(i) for i in bad)})")
    return np.ascontiguousarray(arr, dtype=dtype)


def _environment(env: Any, strength: float = 1.0) -> tuple[np.ndarray, np.ndarray | None]:
    """(constant colour, map or None) times ``strength``. A map's negative or non-finite texels are
    clamped with a warning (HDRIs often hold tiny negative ones); a bad constant colour is an error."""
    if isinstance(strength, bool) or not isinstance(strength, int | float | np.floating) or not (
        math.isfinite(strength) and strength >= 0
    ):
        raise ValueError(f"environment strength must be finite and >= 0, got {strength!r}")
    if env is None:
        return np.asarray(DEFAULT_ENVIRONMENT, dtype=np.float32) * np.float32(strength), None
    arr = np.asarray(env, dtype=np.float32)
    if arr.shape == (3,):
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ValueError(f"environment colour must be finite and >= 0, got {arr.tolist()}")
        return arr * np.float32(strength), None
    if arr.ndim == 3 and arr.shape[2] == 3 and arr.shape[0] >= 1 and arr.shape[1] >= 1:
        arr = finite_clamped(arr, "environment map")
        if strength != 1.0:
            arr = arr * np.float32(strength)
        return np.zeros(3, np.float32), np.ascontiguousarray(arr)
    raise ValueError(f"environment must be an RGB triple or an (H, W, 3) map, got shape {arr.shape}")


def _non_degenerate(pos: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Triangles to keep: no repeated vertex and a non-zero area (computed in double precision)."""
    p64 = pos.astype(np.float64)
    e1 = p64[tri[:, 1]] - p64[tri[:, 0]]
    e2 = p64[tri[:, 2]] - p64[tri[:, 0]]
    area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    return (area2 > 0) & (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])


def _triangle_ids(values: Any, name: str, n_tri: int) -> np.ndarray:
    """Per-triangle ids as uint32 (zeros when not given), one per triangle."""
    if values is None:
        return np.zeros(n_tri, np.uint32)
    ids = _as_array(values, name, np.int64, None)
    if ids.shape[0] != n_tri:
        raise ValueError(f"{name} must have one entry per triangle ({n_tri}), got {ids.shape[0]}")
    return ids.astype(np.uint32)


def _effects(mats: Sequence[Material], lights: Sequence[Light], environment_lights: int,
             environment_map: bool, cutouts: bool) -> list[str]:
    """What the scene's content can show (``stats["effects"]``); the environment map's suns light it as
    soft sun lights."""
    effects = []
    if lights or environment_lights:
        effects.append("direct_light")
    if any(m.is_reflective for m in mats):
        effects.append("reflection")
    if any(m.metallic > 0 and m.roughness > 0 for m in mats):
        effects.append("glossy")
    if any(m.is_refractive for m in mats):
        effects.append("refraction")
    if any(max(m.emission) > 0 for m in mats):
        effects.append("emission")
    if any(light.radius > 0 or light.kind == "area" for light in lights) or environment_lights:
        effects.append("soft_shadows")
    if any(light.kind == "area" for light in lights):
        effects.append("area_lights")
    if environment_map:
        effects.append("environment_map")
    if any(m.base_color_texture is not None for m in mats):
        effects.append("textures")
    if cutouts:
        effects.append("alpha_cutouts")
    return effects


def _material_table(materials: Sequence[Material], texture_count: int) -> np.ndarray:
    rows = []
    for i, m in enumerate(materials):
        if not isinstance(m, Material):
            raise ValueError(f"materials must be sim_core.Material, got {type(m).__name__}")
        tex = -1 if m.base_color_texture is None else m.base_color_texture
        if tex >= texture_count:
            raise ValueError(
                f"material {i} ({m.name!r}) uses texture {tex} but the scene has {texture_count} texture(s)"
            )
        rows.append([*m.base_color, m.metallic, m.roughness, m.transmission, m.ior, *m.emission, m.alpha,
                     ALPHA_MODES.index(m.alpha_mode), m.alpha_cutoff, tex])
    return np.asarray(rows, dtype=np.float32).reshape(-1, _MATERIAL_FIELDS)


def _light_table(lights: Sequence[Light]) -> np.ndarray:
    rows = []
    for light in lights:
        if not isinstance(light, Light):
            raise ValueError(f"lights must be sim_core.Light, got {type(light).__name__}")
        rows.append(
            [
                _LIGHT_KINDS[light.kind],
                *light.position,
                *light.direction,
                *light.color,
                light.intensity,
                light.radius,
                light.spot_angle,
                light.spot_blend,
                0 if light.shape in ("square", "rectangle") else 1,
                light.size,
                light.size_y,
                *light.tangent,
            ]
        )
    return np.asarray(rows, dtype=np.float32).reshape(-1, _LIGHT_FIELDS)


def _native_textures(textures: Sequence[Texture]) -> list[Any]:
    out = []
    for i, t in enumerate(textures):
        if not isinstance(t, Texture):
            raise ValueError(f"textures must be sim_core.Texture, got {type(t).__name__} at index {i}")
        rgba = t.rgba()
        wu, wv = WRAPS.index(t.wrap_u), WRAPS.index(t.wrap_v)
        if rgba.dtype == np.uint8:
            out.append(_core.NativeTexture.from_rgba8(rgba, t.colorspace == "srgb", wu, wv))
        else:
            out.append(_core.NativeTexture.from_rgba32f(rgba, wu, wv))
    return out


class Scene:
    """A triangle scene ready to trace: geometry in a binned-SAH BVH, materials, lights, environment.

    World frame is Blender's (right-handed, Z up). Build with `from_arrays`, `from_obj` or `from_gltf`.
    """

    def __init__(
        self,
        native: Any,
        stats: dict[str, Any],
        content_hash: str,
        materials: list[Material],
        lights: list[Light],
        cameras: list[CameraData],
        source: str = "",
    ) -> None:
        self._native = native
        self._stats = stats
        self._hash = content_hash
        self.materials = materials
        self.lights = lights
        self.cameras = cameras
        self.source = source
        self.object_names: list[str] = []  # indexed by object id, when the loader knows them
        self.textures: list[Texture] = []

    # ---- construction -------------------------------------------------------------------------
    # Long: one validation pass over a dozen optional arrays (each checked where it is read, with its
    # own message) before the single native build; the checks are helpers, the order is the story.
    @classmethod
    def from_arrays(
        cls,
        positions: Any,
        triangles: Any,
        *,
        normals: Any = None,
        material_ids: Any = None,
        object_ids: Any = None,
        materials: Sequence[Material] | None = None,
        lights: Sequence[Light] | None = None,
        environment: Any = None,
        cameras: Sequence[CameraData] | None = None,
        object_names: Sequence[str] | None = None,
        source: str = "",
        uvs: Any = None,
        textures: Sequence[Texture] | None = None,
        environment_strength: float = 1.0,
        environment_rotation: float = 0.0,
    ) -> Scene:
        """Validate flat arrays and build the native scene.

        positions (V, 3) floats; triangles (T, 3) vertex indices; normals (V, 3) per-vertex shading normals;
        material_ids / object_ids (T,) per triangle; uvs (V, 2) texture coordinates (Blender's convention)
        for the materials' base-colour textures (``textures``, shared by index; a textured material in a
        scene without UVs shows its texture's mean colour). environment: see ``SceneData``. Degenerate
        (zero-area) triangles are dropped and counted in `stats["degenerate_dropped"]`; `intersect` still
        reports original triangle indices. Raises ValueError on NaN/Inf, out-of-range indices or an empty
        scene; clamps (with a warning) negative or non-finite environment and float-texture texels.
        """
        pos = _as_array(positions, "positions", np.float32, 3)
        tri = _as_array(triangles, "triangles", np.int64, 3)
        if pos.shape[0] == 0 or tri.shape[0] == 0:
            raise ValueError(f"empty scene: {pos.shape[0]} vertices, {tri.shape[0]} triangles")
        if tri.max() >= pos.shape[0]:
            bad = int(np.argmax(tri.max(axis=1) >= pos.shape[0]))
            raise ValueError(
                f"triangle {bad} references vertex {int(tri[bad].max())} but there are only {pos.shape[0]}"
            )
        n_tri = tri.shape[0]
        nrm = None
        if normals is not None:
            nrm = _as_array(normals, "normals", np.float32, 3)
            if nrm.shape[0] != pos.shape[0]:
                raise ValueError(f"normals must have one row per vertex ({pos.shape[0]}), got {nrm.shape[0]}")
        uv = None
        if uvs is not None:
            uv = _as_array(uvs, "uvs", np.float32, 2)
            if uv.shape[0] != pos.shape[0]:
                raise ValueError(f"uvs must have one row per vertex ({pos.shape[0]}), got {uv.shape[0]}")
        texs = list(textures) if textures else []
        native_textures = _native_textures(texs)
        mats = list(materials) if materials else [Material()]
        mtab = _material_table(mats, len(texs))
        mid = _triangle_ids(material_ids, "material_ids", n_tri)
        if mid.size and mid.max() >= len(mats):
            raise ValueError(f"material id {int(mid.max())} out of range (have {len(mats)} materials)")
        oid = _triangle_ids(object_ids, "object_ids", n_tri)
        if oid.size and oid.max() >= 2**31:
            raise ValueError("object ids must be < 2**31")
        lts = list(lights) if lights else []
        if len(lts) > 32:
            raise ValueError(f"at most 32 lights are supported (one shadow bit each), got {len(lts)}")
        ltab = _light_table(lts)
        env_color, env_map = _environment(environment, environment_strength)
        rotation = float(environment_rotation)
        if not math.isfinite(rotation):
            raise ValueError(f"environment_rotation must be finite, got {environment_rotation!r}")

        keep = _non_degenerate(pos, tri)
        dropped = int(n_tri - np.count_nonzero(keep))
        if not np.any(keep):
            raise ValueError(f"empty scene: all {n_tri} triangles are degenerate (zero area)")
        prim_ids = np.flatnonzero(keep).astype(np.int64)
        native = _core.NativeScene.build(
            pos,
            np.ascontiguousarray(tri[keep], dtype=np.uint32),
            prim_ids,
            nrm,
            np.ascontiguousarray(mid[keep]),
            np.ascontiguousarray(oid[keep]),
            mtab,
            ltab,
            env_color,
            env_map,
            uv,
            native_textures,
            rotation,
        )

        h = hashlib.sha256()
        texture_parts: list[Any] = []
        for t in texs:
            sampling = f"{t.colorspace},{t.wrap_u},{t.wrap_v}".encode()
            texture_parts += [t.image, np.frombuffer(sampling, np.uint8)]
        rot = None if rotation == 0.0 else np.asarray([rotation], np.float64)
        # Parts a scene without UVs, textures or rotation lacks add nothing: old hashes stay valid.
        extra = [a for a in (uv, rot) if a is not None] + texture_parts
        for arr in (pos, tri.astype(np.uint32), nrm, mid, oid, mtab, ltab, env_color, env_map, *extra):
            if arr is None:
                h.update(b"<none>")
            else:
                h.update(str(arr.shape).encode())
                h.update(np.ascontiguousarray(arr).tobytes())
        # The environment map's suns, lit like sun lamps (Environment::lights in the native core).
        env_lights = len(native.environment_lights)
        stats = {
            "triangles": int(np.count_nonzero(keep)),
            "degenerate_dropped": dropped,
            "materials": len(mats),
            "lights": len(lts),
            "environment_lights": env_lights,
            "objects": int(np.unique(oid[keep]).size),
            "effects": _effects(mats, lts, env_lights, env_map is not None, native.has_cutouts),
        }
        scene = cls(native, stats, h.hexdigest(), mats, lts, list(cameras or []), source)
        scene.object_names = [str(n) for n in object_names] if object_names else []
        scene.textures = texs
        return scene

    @classmethod
    def from_scene_data(cls, data: SceneData) -> Scene:
        """Build from what a loader returns."""
        return cls.from_arrays(
            data.positions,
            data.triangles,
            normals=data.normals,
            material_ids=data.material_ids,
            object_ids=data.object_ids,
            materials=data.materials,
            lights=data.lights,
            environment=data.environment,
            cameras=data.cameras,
            object_names=getattr(data, "object_names", None),
            source=data.source,
            uvs=data.uvs,
            textures=data.textures,
            environment_strength=data.environment_strength,
            environment_rotation=data.environment_rotation,
        )

    @classmethod
    def from_scene_file(cls, path: str | os.PathLike[str], **limits: Any) -> Scene:
        """A render-budget scene file (what the add-on's depsgraph translator writes; ``limits``: fields of
        ``sim_core.loaders.scene_file.Limits``)."""
        return cls.from_scene_data(load_scene_file(path, limits=Limits(**limits)))

    @classmethod
    def from_obj(cls, path: str | os.PathLike[str]) -> Scene:
        """Wavefront OBJ (Y-up files are converted to the Z-up world frame by the loader)."""
        return cls.from_scene_data(load_obj(path))

    @classmethod
    def from_gltf(cls, path: str | os.PathLike[str], *, self_contained: bool = False) -> Scene:
        """glTF 2.0 (.glb/.gltf) as Blender exports it: meshes, materials, punctual lights, cameras.
        ``self_contained=True`` reads nothing but the file itself (see :func:`loaders.gltf.load_gltf`)."""
        return cls.from_scene_data(load_gltf(path, self_contained=self_contained))

    # ---- queries --------------------------------------------------------------------------------
    def intersect(
        self, origins: Any, directions: Any, threads: int | None = None, *, tmax: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Closest hit of N rays within (0, tmax): (t float32, inf on miss; prim_id int64 original triangle
        index, -1 on miss).

        t is in units of the direction's length; tmax (N,) defaults to +inf. Multithreaded, GIL released.
        Walks the 4-wide BVH the renderer walks.
        """
        o, d, tm = self._rays(origins, directions, tmax)
        return self._native.intersect(o, d, _threads(threads), tmax=tm)

    def occluded(
        self, origins: Any, directions: Any, tmax: Any = None, threads: int | None = None
    ) -> np.ndarray:
        """Any-hit (shadow-ray) query of N rays: True where a triangle lies in (0, tmax) (default +inf)."""
        o, d, tm = self._rays(origins, directions, tmax)
        return self._native.occluded(o, d, _threads(threads), tmax=tm)

    @staticmethod
    def _rays(origins: Any, directions: Any, tmax: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        o = _as_array(origins, "origins", np.float32, 3)
        d = _as_array(directions, "directions", np.float32, 3)
        if o.shape != d.shape:
            raise ValueError(f"origins {o.shape} and directions {d.shape} must have the same shape")
        if np.any(~np.any(d != 0, axis=1)):
            raise ValueError("directions must be non-zero")
        if tmax is None:
            return o, d, None
        tm = np.asarray(tmax, dtype=np.float32)
        if tm.shape != (o.shape[0],):
            raise ValueError(f"tmax must have shape ({o.shape[0]},), got {tm.shape}")
        if np.isnan(tm).any() or (tm < 0).any():
            raise ValueError("tmax must be >= 0 (inf allowed)")
        return o, d, np.ascontiguousarray(tm)

    @property
    def stats(self) -> dict[str, Any]:
        """triangles, degenerate_dropped, materials, lights, environment_lights (the map's suns, lit as sun
        lights), objects, effects."""
        return dict(self._stats)

    @property
    def content_hash(self) -> str:
        """sha256 over geometry, materials, lights and environment (stable across runs)."""
        return self._hash

    @property
    def bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        return self._native.bounds

    @property
    def native(self) -> Any:
        return self._native

    def __repr__(self) -> str:
        s = self._stats
        return f"Scene({s['triangles']} triangles, {s['lights']} lights, {self._hash[:12]})"


def _threads(threads: int | None) -> int:
    if threads is None:
        return max(1, os.cpu_count() or 1)
    if isinstance(threads, bool) or not isinstance(threads, int | np.integer) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    return int(threads)
