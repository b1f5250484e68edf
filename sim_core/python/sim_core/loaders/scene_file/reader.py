"""Reading a scene file: the ZIP container and its entries checked against the manifest and the limits,
arrays read without pickles; the manifest's records become scene data in :mod:`.records`."""

from __future__ import annotations

import json
import math
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ...scene_data import SceneData
from .format import DEFAULT_LIMITS, FORMAT, MANIFEST, VERSION, Limits, SceneFile, is_texture_name
from .records import scene_from_manifest

_ZIP_MAGIC = b"PK\x03\x04"


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
    unknown = {n for n in declared if n not in _ARRAY_SPECS and not is_texture_name(n)}
    if unknown:
        raise ValueError(f"scene manifest names unknown arrays: {sorted(unknown)}")
    expected_entries = {MANIFEST} | {f"arrays/{n}.npy" for n in declared}
    if set(names) != expected_entries:
        extra, missing = set(names) - expected_entries, expected_entries - set(names)
        raise ValueError(f"scene file entries do not match its manifest (extra {sorted(extra)}, "
                         f"missing {sorted(missing)})")
    arrays = {name: _array(zf, name, spec, limits) for name, spec in declared.items()}
    return scene_from_manifest(manifest, arrays, limits)


def _json(raw: bytes) -> Any:
    def reject(token: str) -> Any:
        raise ValueError(f"scene manifest holds a non-finite number ({token})")

    try:
        return json.loads(raw.decode("utf-8"), parse_constant=reject)
    except json.JSONDecodeError as exc:
        raise ValueError(f"scene manifest is not valid JSON ({exc.msg} at character {exc.pos})") from None


def _array(zf: zipfile.ZipFile, name: str, spec: Any, limits: Limits) -> np.ndarray:
    dtypes, cols = _TEXTURE_SPEC if is_texture_name(name) else _ARRAY_SPECS[name]
    if not isinstance(spec, dict):
        raise ValueError(f"scene manifest: array {name!r} must be described by an object")
    dtype, shape = spec.get("dtype"), spec.get("shape")
    if dtype not in dtypes:
        raise ValueError(f"array {name!r} must have dtype {' or '.join(dtypes)}, got {dtype!r}")
    if not (isinstance(shape, list) and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                            for s in shape)):
        raise ValueError(f"array {name!r}: shape must be a list of non-negative integers, got {shape!r}")
    texture = is_texture_name(name)
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
