"""Writing a scene file: the same scene always gives the same bytes (stored entries in a fixed order with
fixed timestamps and attributes; sorted-key JSON)."""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ...scene_data import SceneData
from .format import FORMAT, MANIFEST, VERSION

_EPOCH = (1980, 1, 1, 0, 0, 0)


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
