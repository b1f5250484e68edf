"""The manifest's records as scene data: every field type-checked and every index range-checked against
the arrays and the limits (scene files come from clients)."""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import Any

import numpy as np

from ...scene_data import CameraData, Light, Material, SceneData, Texture
from .format import Limits, SceneFile, is_texture_name


def _string(value: Any, what: str, limits: Limits) -> str:
    if not isinstance(value, str):
        raise ValueError(f"{what} must be a string, got {type(value).__name__}")
    if len(value) > limits.max_string:
        raise ValueError(f"{what} longer than {limits.max_string} characters")
    return value


def _fields(cls: Any, record: Any, what: str, limits: Limits) -> dict[str, Any]:
    if not isinstance(record, dict):
        raise ValueError(f"{what} must be an object")
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = set(record) - known
    if unknown:
        raise ValueError(f"{what} has unknown fields {sorted(unknown)}")
    out: dict[str, Any] = {}
    for key, value in record.items():
        if isinstance(value, str):
            out[key] = _string(value, f"{what} {key}", limits)
        elif isinstance(value, list):
            if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
                raise ValueError(f"{what} {key} must be a list of numbers")
            out[key] = tuple(float(v) for v in value)
        elif value is None or (isinstance(value, int | float) and not isinstance(value, bool)):
            out[key] = value
        else:
            raise ValueError(f"{what} {key} has an unsupported value {value!r}")
    return out


def scene_from_manifest(manifest: dict[str, Any], arrays: dict[str, np.ndarray], limits: Limits) -> SceneFile:
    """The scene file's content, each part validated in turn (geometry, textures, materials and lights,
    object names, cameras, environment, notes)."""
    pos, tri, normals, uvs = _geometry(arrays)
    textures = _textures(manifest.get("textures", []), arrays, limits)
    materials, lights = _materials_and_lights(manifest, arrays, textures, limits)
    names = _object_names(manifest, arrays, limits)
    cameras_raw = manifest.get("cameras", [])
    if not isinstance(cameras_raw, list) or len(cameras_raw) > 1024:
        raise ValueError("scene manifest: 'cameras' must be a list of at most 1024")
    cameras = [_camera(c, i, limits) for i, c in enumerate(cameras_raw)]
    env_record = manifest.get("environment", {"kind": "default"})
    environment = _environment(env_record, arrays)
    strength, rotation = env_record.get("strength", 1.0), env_record.get("rotation", 0.0)
    for label, v in (("strength", strength), ("rotation", rotation)):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ValueError(f"environment {label} must be a finite number, got {v!r}")
    if strength < 0:
        raise ValueError(f"environment strength must be >= 0, got {strength}")
    notes = _notes(manifest, limits)
    material_ids, object_ids = arrays.get("material_ids"), arrays.get("object_ids")
    data = SceneData(
        positions=np.array(pos, dtype=np.float32),
        triangles=np.array(tri, dtype=np.uint32),
        normals=None if normals is None else np.array(normals, dtype=np.float32),
        material_ids=None if material_ids is None else np.array(material_ids, dtype=np.uint32),
        object_ids=None if object_ids is None else np.array(object_ids, dtype=np.uint32),
        materials=materials,
        lights=lights,
        cameras=cameras,
        environment=environment,
        environment_strength=float(strength),
        environment_rotation=float(rotation),
        object_names=names,
        uvs=None if uvs is None else np.array(uvs, dtype=np.float32),
        textures=textures,
    )
    return SceneFile(data=data, notes=notes, version=int(manifest["version"]))


def _geometry(arrays: dict[str, np.ndarray]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(positions, triangles, normals, uvs), checked: not empty, finite, indices and row counts in range."""
    for required in ("positions", "triangles"):
        if required not in arrays:
            raise ValueError(f"scene file lacks the {required!r} array")
    pos, tri = arrays["positions"], arrays["triangles"]
    n_vert, n_tri = pos.shape[0], tri.shape[0]
    if n_vert == 0 or n_tri == 0:
        raise ValueError(f"empty scene: {n_vert} vertices, {n_tri} triangles")
    if not np.all(np.isfinite(pos)):
        raise ValueError("positions must be finite (NaN or Inf found)")
    if int(tri.max()) >= n_vert:
        raise ValueError(f"a triangle references vertex {int(tri.max())} but there are only {n_vert}")
    normals, uvs = arrays.get("normals"), arrays.get("uvs")
    for key, per_vertex in (("normals", normals), ("uvs", uvs)):
        if per_vertex is None:
            continue
        if per_vertex.shape[0] != n_vert:
            raise ValueError(f"{key} must have one row per vertex ({n_vert}), got {per_vertex.shape[0]}")
        if not np.all(np.isfinite(per_vertex)):
            raise ValueError(f"{key} must be finite (NaN or Inf found)")
    for key in ("material_ids", "object_ids"):
        if key in arrays and arrays[key].shape[0] != n_tri:
            raise ValueError(f"{key} must have one entry per triangle ({n_tri}), got {arrays[key].shape[0]}")
    return pos, tri, normals, uvs


def _materials_and_lights(manifest: dict[str, Any], arrays: dict[str, np.ndarray], textures: list[Texture],
                          limits: Limits) -> tuple[list[Material], list[Light]]:
    materials_raw = manifest.get("materials", [])
    lights_raw = manifest.get("lights", [])
    if not isinstance(materials_raw, list) or len(materials_raw) > limits.max_materials:
        raise ValueError(f"scene manifest: 'materials' must be a list of at most {limits.max_materials}")
    if not isinstance(lights_raw, list) or len(lights_raw) > 32:
        raise ValueError("scene manifest: 'lights' must be a list of at most 32 (one shadow bit each)")
    materials = [Material(**_fields(Material, r, f"material {i}", limits))
                 for i, r in enumerate(materials_raw)]
    lights = [Light(**_fields(Light, r, f"light {i}", limits)) for i, r in enumerate(lights_raw)]
    for i, m in enumerate(materials):
        if m.base_color_texture is not None and m.base_color_texture >= len(textures):
            raise ValueError(f"material {i} uses texture {m.base_color_texture} but the file has "
                             f"{len(textures)} texture(s)")
    material_ids = arrays.get("material_ids")
    if material_ids is not None and material_ids.size and int(material_ids.max()) >= max(1, len(materials)):
        raise ValueError(f"material id {int(material_ids.max())} out of range ({len(materials)} materials)")
    return materials, lights


def _object_names(manifest: dict[str, Any], arrays: dict[str, np.ndarray], limits: Limits) -> list[str]:
    names = manifest.get("object_names", [])
    if not isinstance(names, list) or len(names) > limits.max_objects:
        raise ValueError(f"scene manifest: 'object_names' must be a list of at most {limits.max_objects}")
    names = [_string(n, "object name", limits) for n in names]
    object_ids = arrays.get("object_ids")
    if object_ids is not None and object_ids.size and names and int(object_ids.max()) >= len(names):
        raise ValueError(f"object id {int(object_ids.max())} out of range ({len(names)} object names)")
    return names


def _notes(manifest: dict[str, Any], limits: Limits) -> list[dict[str, str]]:
    notes_raw = manifest.get("notes", [])
    if not isinstance(notes_raw, list) or len(notes_raw) > limits.max_notes:
        raise ValueError(f"scene manifest: 'notes' must be a list of at most {limits.max_notes}")
    notes = []
    for i, n in enumerate(notes_raw):
        if not isinstance(n, dict) or set(n) - {"severity", "subject", "message"}:
            raise ValueError(f"note {i} must be an object with severity, subject and message")
        severity = n.get("severity", "info")
        if severity not in ("info", "warning"):
            raise ValueError(f"note {i}: severity must be 'info' or 'warning'")
        notes.append({"severity": severity, "subject": _string(n.get("subject", ""), f"note {i}", limits),
                      "message": _string(n.get("message", ""), f"note {i}", limits)})
    return notes


def _textures(records: Any, arrays: dict[str, np.ndarray], limits: Limits) -> list[Texture]:
    if not isinstance(records, list) or len(records) > limits.max_textures:
        raise ValueError(f"scene manifest: 'textures' must be a list of at most {limits.max_textures}")
    named = {n for n in arrays if is_texture_name(n)}
    wanted = [r.get("array") if isinstance(r, dict) else None for r in records]
    if sorted(named) != sorted(w for w in wanted if isinstance(w, str)) or len(set(wanted)) != len(wanted):
        raise ValueError("scene manifest: each texture must name its own texture_<i> array, and every "
                         "texture array must belong to one texture")
    texels = sum(math.prod(arrays[n].shape[:2]) for n in named)
    if texels > limits.max_texture_texels:
        raise ValueError(f"textures hold {texels} texels, over the limit of {limits.max_texture_texels}")
    out = []
    for i, record in enumerate(records):
        if set(record) - {"array", "colorspace", "wrap_u", "wrap_v", "name"}:
            raise ValueError(f"texture {i} has unknown fields {sorted(set(record) - {'array'})}")
        fields = {k: _string(record[k], f"texture {i} {k}", limits)
                  for k in ("colorspace", "wrap_u", "wrap_v", "name") if k in record}
        image = arrays[record["array"]]
        image = np.array(image) if image.dtype == np.uint8 else np.array(image, dtype=np.float32)
        out.append(Texture(image=image, **fields))  # validates sizes, colour space, wraps; clamps floats
    return out


def _camera(record: Any, i: int, limits: Limits) -> CameraData:
    if not isinstance(record, dict) or set(record) - {"matrix_world", "vfov", "aspect", "name"}:
        raise ValueError(f"camera {i} must be an object with matrix_world, vfov, aspect, name")
    m = np.asarray(record.get("matrix_world"), dtype=np.float64) if _numbers(record.get("matrix_world")) \
        else None
    if m is None or m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"camera {i}: matrix_world must be a finite 4x4 matrix")
    vfov, aspect = record.get("vfov"), record.get("aspect", 16 / 9)
    for label, v in (("vfov", vfov), ("aspect", aspect)):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
            raise ValueError(f"camera {i}: {label} must be a positive number, got {v!r}")
    if vfov >= math.pi:
        raise ValueError(f"camera {i}: vfov must be below pi radians, got {vfov}")
    return CameraData(matrix_world=m, vfov=float(vfov), aspect=float(aspect),
                      name=_string(record.get("name", ""), f"camera {i} name", limits))


def _numbers(value: Any) -> bool:
    if isinstance(value, list):
        return all(_numbers(v) for v in value)
    return isinstance(value, int | float) and not isinstance(value, bool)


def _environment(record: Any, arrays: dict[str, np.ndarray]
                 ) -> np.ndarray | tuple[float, float, float] | None:
    if not isinstance(record, dict) or set(record) - {"kind", "color", "array", "strength", "rotation"}:
        raise ValueError("scene manifest: 'environment' must be an object with kind, color or array, "
                         "strength and rotation")
    kind = record.get("kind")
    if kind == "default":
        env = None
    elif kind == "color":
        color = record.get("color")
        if not (_numbers(color) and isinstance(color, list) and len(color) == 3):
            raise ValueError("environment colour must be three numbers")
        if not all(math.isfinite(c) and c >= 0 for c in color):
            raise ValueError(f"environment colour must be finite and >= 0, got {color}")
        env = (float(color[0]), float(color[1]), float(color[2]))
    elif kind == "map":
        if record.get("array") != "environment" or "environment" not in arrays:
            raise ValueError("environment map must name the 'environment' array, which must be present")
        img = np.array(arrays["environment"], dtype=np.float32)
        if img.shape[0] < 1 or img.shape[1] < 1:
            raise ValueError(f"environment map must not be empty, got shape {list(img.shape)}")
        bad = ~np.isfinite(img) | (img < 0)
        if bad.any():
            warnings.warn(f"environment map: clamped {int(bad.sum())} negative or non-finite texel value(s)",
                          stacklevel=4)
            img[bad] = 0.0
        env = img
    else:
        raise ValueError(f"environment kind must be 'default', 'color' or 'map', got {kind!r}")
    if kind != "map" and "environment" in arrays:
        raise ValueError("an 'environment' array is present but the environment is not a map")
    return env
