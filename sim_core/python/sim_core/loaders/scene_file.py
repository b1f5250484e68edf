"""The render-budget scene file: a ``SceneData`` in one self-contained, safe, deterministic file.

What the add-on's depsgraph translator produces travels to jobs (local or on the service) in this format,
so a job optimises exactly the scene the render engine renders. Layout (version 1):

- a ZIP archive whose entries are all *stored* (uncompressed: no decompression bombs, and the bytes are a
  pure function of the content), written in a fixed order with fixed timestamps and attributes;
- ``manifest.json`` (first entry, UTF-8, sorted keys): ``format`` = ``"render-budget-scene"``, ``version``,
  ``arrays`` (name -> dtype and shape), ``materials`` and ``lights`` (the fields of
  ``sim_core.Material`` / ``sim_core.Light``), ``cameras``, ``environment`` (``{"kind": "default"}``,
  ``{"kind": "color", "color": [r, g, b]}`` or ``{"kind": "map", "array": "environment"}``, each with
  ``strength`` and ``rotation``), ``textures`` (``{array, colorspace, wrap_u, wrap_v, name}``),
  ``object_names`` and ``notes`` (what the translator approximated: ``{severity, subject, message}``);
- ``arrays/<name>.npy``: NumPy format 1.0, little-endian, C order, read with ``allow_pickle=False``:
  ``positions`` (V, 3) <f4, ``triangles`` (T, 3) <u4, optional ``normals`` (V, 3) <f4 and ``uvs`` (V, 2) <f4,
  ``material_ids`` and ``object_ids`` (T,) <u4, ``environment`` (H, W, 3) <f4 or <f2, ``texture_<i>``
  (H, W, C) |u1, <f4 or <f2 with C in 1..4 (row 0 at the top).

The scene id of a file is the SHA-256 of its bytes; the same scene always writes the same bytes. Reading
validates like any upload: entry names, sizes against the limits, dtypes and shapes against the manifest,
finite values, index ranges; errors are ``ValueError`` naming the problem (never a path or a Python
exception's internals). Negative or non-finite environment texels are clamped with a warning.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import math
import os
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..scene_data import CameraData, Light, Material, SceneData, Texture

FORMAT = "render-budget-scene"
VERSION = 1
SUFFIX = ".rbscene"
MEDIA_TYPE = "application/vnd.render-budget.scene+zip"
MANIFEST = "manifest.json"
_ZIP_MAGIC = b"PK\x03\x04"
_EPOCH = (1980, 1, 1, 0, 0, 0)


@dataclass(frozen=True)
class Limits:
    """What a reader accepts (the service passes its own; the defaults suit a desktop job)."""

    max_bytes: int = 2 * 1024**3
    max_triangles: int = 50_000_000
    max_vertices: int = 100_000_000
    max_objects: int = 1_000_000
    max_materials: int = 65_536
    max_environment_texels: int = 64 * 1024 * 1024
    max_texture_texels: int = 256 * 1024 * 1024  # all textures together
    max_textures: int = 4096
    max_manifest_bytes: int = 64 * 1024 * 1024
    max_string: int = 4096
    max_notes: int = 10_000


DEFAULT_LIMITS = Limits()


@dataclass
class SceneFile:
    """A scene file's content: the scene data and the translator's notes (dicts: severity, subject,
    message)."""

    data: SceneData
    notes: list[dict[str, str]] = field(default_factory=list)
    version: int = VERSION


# -- writing ---------------------------------------------------------------------------------------------
def scene_file_bytes(data: SceneData, notes: Any = ()) -> bytes:
    """The file's bytes for ``data`` (deterministic). ``notes``: Note objects (``to_dict``) or dicts."""
    arrays: dict[str, np.ndarray] = {
        "positions": np.ascontiguousarray(data.positions, dtype="<f4"),
        "triangles": np.ascontiguousarray(data.triangles, dtype="<u4"),
    }
    n_tri = arrays["triangles"].shape[0]
    if data.normals is not None:
        arrays["normals"] = np.ascontiguousarray(data.normals, dtype="<f4")
    if data.uvs is not None:
        arrays["uvs"] = np.ascontiguousarray(data.uvs, dtype="<f4")
    arrays["material_ids"] = np.ascontiguousarray(
        np.zeros(n_tri) if data.material_ids is None else data.material_ids, dtype="<u4")
    arrays["object_ids"] = np.ascontiguousarray(
        np.zeros(n_tri) if data.object_ids is None else data.object_ids, dtype="<u4")
    environment: dict[str, Any]
    if data.environment is None:
        environment = {"kind": "default"}
    elif isinstance(data.environment, np.ndarray) and data.environment.ndim == 3:
        arrays["environment"] = _half_if_exact(np.ascontiguousarray(data.environment, dtype="<f4"))
        environment = {"kind": "map", "array": "environment"}
    else:
        environment = {"kind": "color", "color": [float(c) for c in np.asarray(data.environment).reshape(-1)]}
    environment.update(strength=float(data.environment_strength), rotation=float(data.environment_rotation))
    textures = []
    for i, t in enumerate(data.textures):
        img = t.image if t.image.dtype == np.uint8 else _half_if_exact(np.ascontiguousarray(t.image, "<f4"))
        arrays[f"texture_{i}"] = np.ascontiguousarray(img)
        textures.append({"array": f"texture_{i}", "colorspace": t.colorspace, "wrap_u": t.wrap_u,
                         "wrap_v": t.wrap_v, "name": t.name})
    object_names = list(data.object_names) or [f"object {i}" for i in range(_count(arrays["object_ids"]))]
    manifest = {
        "format": FORMAT,
        "version": VERSION,
        "arrays": {name: {"dtype": a.dtype.str, "shape": list(a.shape)} for name, a in arrays.items()},
        "materials": [_record(m) for m in data.materials],
        "lights": [_record(lt) for lt in data.lights],
        "cameras": [{"matrix_world": np.asarray(c.matrix_world, dtype=np.float64).reshape(4, 4).tolist(),
                     "vfov": float(c.vfov), "aspect": float(c.aspect), "name": str(c.name)}
                    for c in data.cameras],
        "environment": environment,
        "textures": textures,
        "object_names": [str(n) for n in object_names],
        "notes": [_note_dict(n) for n in notes],
    }
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        _write_entry(zf, MANIFEST, json.dumps(manifest, sort_keys=True, separators=(",", ":"),
                                              allow_nan=False).encode("utf-8"))
        for name, a in arrays.items():
            out = io.BytesIO()
            np.lib.format.write_array(out, a, version=(1, 0), allow_pickle=False)
            _write_entry(zf, f"arrays/{name}.npy", out.getvalue())
    return buf.getvalue()


def write_scene_file(path: str | os.PathLike[str], data: SceneData, notes: Any = ()) -> str:
    """Write ``data`` (and the translator's notes) to ``path``; returns the scene id (SHA-256 of the
    bytes)."""
    blob = scene_file_bytes(data, notes)
    p = Path(path)
    tmp = p.with_name(p.name + ".part")
    tmp.write_bytes(blob)
    os.replace(tmp, p)
    return hashlib.sha256(blob).hexdigest()


def _write_entry(zf: zipfile.ZipFile, name: str, payload: bytes) -> None:
    info = zipfile.ZipInfo(name, date_time=_EPOCH)
    info.compress_type = zipfile.ZIP_STORED
    info.create_system = 3
    info.external_attr = 0o644 << 16
    zf.writestr(info, payload)


def _half_if_exact(image: np.ndarray) -> np.ndarray:
    """Half precision when that is exact (HDRIs are usually stored as half floats), else float32."""
    half = image.astype("<f2")
    return half if np.array_equal(half.astype("<f4"), image, equal_nan=True) else image


def _count(object_ids: np.ndarray) -> int:
    return int(object_ids.max()) + 1 if object_ids.size else 0


def _record(obj: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, tuple):
            v = [float(x) for x in v]
        elif isinstance(v, float | np.floating):
            v = float(v)
        elif isinstance(v, np.integer):
            v = int(v)
        out[f.name] = v
    return out


def _note_dict(note: Any) -> dict[str, str]:
    d = note.to_dict() if hasattr(note, "to_dict") else dict(note)
    return {"severity": str(d.get("severity", "info")), "subject": str(d.get("subject", "")),
            "message": str(d.get("message", ""))}


# -- reading ---------------------------------------------------------------------------------------------
def is_scene_file(head: bytes | str | os.PathLike[str]) -> bool:
    """True for the first bytes (or the path) of a scene file: a ZIP whose first entry is the manifest."""
    if not isinstance(head, bytes):
        try:
            with open(head, "rb") as f:
                head = f.read(30 + len(MANIFEST))
        except OSError:
            return False
    if len(head) < 30 + len(MANIFEST) or not head.startswith(_ZIP_MAGIC):
        return False
    name_len = int.from_bytes(head[26:28], "little")
    return name_len == len(MANIFEST) and head[30:30 + name_len] == MANIFEST.encode()


def load_scene_file(path: str | os.PathLike[str], *, limits: Limits = DEFAULT_LIMITS) -> SceneData:
    """The scene data of a scene file (see :func:`read_scene_file`)."""
    return read_scene_file(path, limits=limits).data


def read_scene_file(path: str | os.PathLike[str], *, limits: Limits = DEFAULT_LIMITS) -> SceneFile:
    """Read and validate a scene file. FileNotFoundError if it is missing; ValueError naming the problem
    for anything else (not a scene file, a newer version, sizes over ``limits``, bad arrays or fields)."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"scene file not found: {p}")
    size = p.stat().st_size
    if size > limits.max_bytes:
        raise ValueError(f"scene file of {size} bytes exceeds the limit of {limits.max_bytes} bytes")
    try:
        with zipfile.ZipFile(p) as zf:
            content = _read(zf, size, limits)
        content.data.source = str(p)
        return content
    except zipfile.BadZipFile as exc:
        raise ValueError(f"not a readable scene file (ZIP: {exc})") from None
    except (KeyError, TypeError, AttributeError, IndexError, OverflowError) as exc:
        raise ValueError(f"malformed scene file ({type(exc).__name__}: {exc})") from None
    except (MemoryError, RecursionError) as exc:
        raise ValueError(f"scene file too large to load ({type(exc).__name__})") from None
    except (EOFError, OSError, NotImplementedError, UnicodeDecodeError) as exc:
        raise ValueError(f"corrupt scene file ({type(exc).__name__})") from None


_ARRAY_SPECS: dict[str, tuple[tuple[str, ...], int | None]] = {
    # name: (accepted dtypes, columns (None: 1-D))
    "positions": (("<f4",), 3),
    "triangles": (("<u4",), 3),
    "normals": (("<f4",), 3),
    "material_ids": (("<u4",), None),
    "object_ids": (("<u4",), None),
    "uvs": (("<f4",), 2),
    "environment": (("<f4", "<f2"), 3),
}
_TEXTURE_SPEC = (("|u1", "<f4", "<f2"), None)


def _read(zf: zipfile.ZipFile, size: int, limits: Limits) -> SceneFile:
    infos = zf.infolist()
    if not infos or infos[0].filename != MANIFEST:
        raise ValueError(f"not a scene file: the first entry must be {MANIFEST}")
    names = [i.filename for i in infos]
    if len(set(names)) != len(names):
        raise ValueError("scene file has duplicate entries")
    total = 0
    for info in infos:
        if info.compress_type != zipfile.ZIP_STORED:
            raise ValueError(f"scene file entry {info.filename!r} is compressed; entries must be stored")
        if info.flag_bits & 0x1:
            raise ValueError("scene file entries must not be encrypted")
        total += info.file_size
    if total > size:
        raise ValueError("scene file entries declare more bytes than the file holds")
    manifest_info = infos[0]
    if manifest_info.file_size > limits.max_manifest_bytes:
        raise ValueError(f"scene manifest of {manifest_info.file_size} bytes exceeds the limit")
    manifest = _json(zf.read(manifest_info))
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise ValueError(f"not a scene file: manifest format must be {FORMAT!r}")
    version = manifest.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ValueError(f"scene file version must be a positive integer, got {version!r}")
    if version > VERSION:
        raise ValueError(f"scene file version {version} is newer than this reader ({VERSION}): update")
    declared = manifest.get("arrays")
    if not isinstance(declared, dict):
        raise ValueError("scene manifest: 'arrays' must be an object")
    unknown = {n for n in declared if n not in _ARRAY_SPECS and not _is_texture_name(n)}
    if unknown:
        raise ValueError(f"scene manifest names unknown arrays: {sorted(unknown)}")
    expected_entries = {MANIFEST} | {f"arrays/{n}.npy" for n in declared}
    if set(names) != expected_entries:
        extra, missing = set(names) - expected_entries, expected_entries - set(names)
        raise ValueError(f"scene file entries do not match its manifest (extra {sorted(extra)}, "
                         f"missing {sorted(missing)})")
    arrays = {name: _array(zf, name, spec, limits) for name, spec in declared.items()}
    return _scene(manifest, arrays, limits)


def _is_texture_name(name: str) -> bool:
    return name.startswith("texture_") and name[8:].isdigit() and str(int(name[8:])) == name[8:]


def _json(raw: bytes) -> Any:
    def reject(token: str) -> Any:
        raise ValueError(f"scene manifest holds a non-finite number ({token})")

    try:
        return json.loads(raw.decode("utf-8"), parse_constant=reject)
    except json.JSONDecodeError as exc:
        raise ValueError(f"scene manifest is not valid JSON ({exc.msg} at character {exc.pos})") from None


def _array(zf: zipfile.ZipFile, name: str, spec: Any, limits: Limits) -> np.ndarray:
    dtypes, cols = _TEXTURE_SPEC if _is_texture_name(name) else _ARRAY_SPECS[name]
    if not isinstance(spec, dict):
        raise ValueError(f"scene manifest: array {name!r} must be described by an object")
    dtype, shape = spec.get("dtype"), spec.get("shape")
    if dtype not in dtypes:
        raise ValueError(f"array {name!r} must have dtype {' or '.join(dtypes)}, got {dtype!r}")
    if not (isinstance(shape, list) and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                            for s in shape)):
        raise ValueError(f"array {name!r}: shape must be a list of non-negative integers, got {shape!r}")
    texture = _is_texture_name(name)
    want_ndim = 3 if name == "environment" or texture else (1 if cols is None else 2)
    if len(shape) != want_ndim or (cols is not None and shape[-1] != cols):
        raise ValueError(f"array {name!r} has shape {shape}, expected {want_ndim} dimensions"
                         + ("" if cols is None else f" with {cols} in the last"))
    if texture and not 1 <= shape[-1] <= 4:
        raise ValueError(f"array {name!r} must have 1 to 4 channels, got {shape[-1]}")
    count = math.prod(shape)
    caps = {"positions": limits.max_vertices * 3, "normals": limits.max_vertices * 3,
            "uvs": limits.max_vertices * 2, "triangles": limits.max_triangles * 3,
            "material_ids": limits.max_triangles, "object_ids": limits.max_triangles,
            "environment": limits.max_environment_texels * 3}
    if count > (limits.max_texture_texels * 4 if texture else caps[name]):
        raise ValueError(f"array {name!r} of shape {shape} exceeds the limits")
    info = zf.getinfo(f"arrays/{name}.npy")
    with zf.open(info) as f:
        magic = np.lib.format.read_magic(f)
        if magic != (1, 0):
            raise ValueError(f"array {name!r}: NumPy format {magic} (expected 1.0)")
        hdr_shape, fortran, hdr_dtype = np.lib.format.read_array_header_1_0(f)
        if hdr_dtype.hasobject or hdr_dtype.str != dtype or list(hdr_shape) != shape or fortran:
            raise ValueError(f"array {name!r}: stored as {hdr_dtype.str} {list(hdr_shape)}"
                             f"{' Fortran order' if fortran else ''}, manifest says {dtype} {shape}")
        nbytes = count * hdr_dtype.itemsize
        raw = f.read(nbytes + 1)
    if len(raw) != nbytes:
        raise ValueError(f"array {name!r}: {len(raw)} data bytes, expected {nbytes}")
    return np.frombuffer(raw, dtype=hdr_dtype).reshape(shape)


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


def _scene(manifest: dict[str, Any], arrays: dict[str, np.ndarray], limits: Limits) -> SceneFile:
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
    textures = _textures(manifest.get("textures", []), arrays, limits)

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

    names = manifest.get("object_names", [])
    if not isinstance(names, list) or len(names) > limits.max_objects:
        raise ValueError(f"scene manifest: 'object_names' must be a list of at most {limits.max_objects}")
    names = [_string(n, "object name", limits) for n in names]
    object_ids = arrays.get("object_ids")
    if object_ids is not None and object_ids.size and names and int(object_ids.max()) >= len(names):
        raise ValueError(f"object id {int(object_ids.max())} out of range ({len(names)} object names)")

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


def _textures(records: Any, arrays: dict[str, np.ndarray], limits: Limits) -> list[Texture]:
    if not isinstance(records, list) or len(records) > limits.max_textures:
        raise ValueError(f"scene manifest: 'textures' must be a list of at most {limits.max_textures}")
    named = {n for n in arrays if _is_texture_name(n)}
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
