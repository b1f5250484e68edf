"""Binary data of a glTF document: buffer views, accessors (strided, sparse, normalized) and a
primitive's index list as triangles."""

from __future__ import annotations

from typing import Any

import numpy as np

from .document import Document

_COMPONENT_DTYPES = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}
_NORMALIZE_DIVISORS = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: Upper bound on any accessor's element count (a hostile count must not allocate gigabytes).
_MAX_ELEMENTS = 1 << 28


def buffer_view_bytes(doc: Document, index: int) -> tuple[memoryview, int | None]:
    views = doc.gltf.get("bufferViews", [])
    if not 0 <= index < len(views):
        raise ValueError(f"{doc.path}: bufferView {index} does not exist")
    view = views[index]
    buf_index = int(view["buffer"])
    if not 0 <= buf_index < len(doc.buffers):
        raise ValueError(f"{doc.path}: bufferView {index} refers to missing buffer {buf_index}")
    buf = doc.buffers[buf_index]
    start = int(view.get("byteOffset", 0))
    length = int(view["byteLength"])
    if start < 0 or length < 0 or start + length > len(buf):
        raise ValueError(
            f"{doc.path}: bufferView {index} (bytes {start}..{start + length}) exceeds buffer "
            f"{buf_index} of {len(buf)} bytes (truncated file?)"
        )
    stride = view.get("byteStride")
    return memoryview(buf)[start : start + length], (int(stride) if stride else None)


def _strided(raw: memoryview, offset: int, count: int, ncomp: int, dtype: np.dtype, stride: int | None,
             what: str) -> np.ndarray:
    if count < 0:
        raise ValueError(f"{what}: negative count")
    elem = ncomp * dtype.itemsize
    stride = stride or elem
    if stride < elem:
        raise ValueError(f"{what}: byteStride {stride} smaller than the element size {elem}")
    needed = offset + (stride * (count - 1) + elem if count else 0)
    if offset < 0 or needed > len(raw):
        raise ValueError(f"{what}: needs {needed} bytes but its bufferView has {len(raw)} (truncated file?)")
    if count == 0:
        return np.zeros((0, ncomp), dtype=dtype)
    base = np.frombuffer(raw, dtype=np.uint8, count=needed - offset, offset=offset)
    rows = np.lib.stride_tricks.as_strided(base, shape=(count, elem), strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dtype).reshape(count, ncomp)


def read_accessor(doc: Document, index: int) -> np.ndarray:
    """Decode one accessor to a (count, ncomp) array: float64 for normalized/float data, else integers."""
    accessors = doc.gltf.get("accessors", [])
    if not 0 <= index < len(accessors):
        raise ValueError(f"{doc.path}: accessor {index} does not exist")
    acc = accessors[index]
    what = f"{doc.path}: accessor {index}"
    ctype = int(acc["componentType"])
    if ctype not in _COMPONENT_DTYPES:
        raise ValueError(f"{what}: unknown componentType {ctype}")
    dtype = _COMPONENT_DTYPES[ctype]
    acc_type = acc.get("type")
    if acc_type not in ("SCALAR", "VEC2", "VEC3", "VEC4"):
        raise ValueError(f"{what}: type {acc_type!r} is not supported for geometry")
    ncomp = _TYPE_SIZES[acc_type]
    count = int(acc["count"])
    if not 0 <= count <= _MAX_ELEMENTS:
        raise ValueError(f"{what}: count {count} outside [0, {_MAX_ELEMENTS}]")
    if "bufferView" in acc:
        raw, stride = buffer_view_bytes(doc, int(acc["bufferView"]))
        out = _strided(raw, int(acc.get("byteOffset", 0)), count, ncomp, dtype, stride, what)
    else:
        out = np.zeros((count, ncomp), dtype=dtype)

    sparse = acc.get("sparse")
    if sparse:
        scount = int(sparse["count"])
        sidx = sparse["indices"]
        itype = int(sidx["componentType"])
        if itype not in (5121, 5123, 5125):
            raise ValueError(f"{what}: sparse indices componentType {itype} not allowed")
        raw_i, _ = buffer_view_bytes(doc, int(sidx["bufferView"]))
        idx = _strided(raw_i, int(sidx.get("byteOffset", 0)), scount, 1, _COMPONENT_DTYPES[itype], None,
                       what + " sparse indices")[:, 0].astype(np.int64)
        if scount and (idx.min() < 0 or idx.max() >= count):
            raise ValueError(f"{what}: sparse index out of range [0, {count})")
        svals = sparse["values"]
        raw_v, _ = buffer_view_bytes(doc, int(svals["bufferView"]))
        vals = _strided(raw_v, int(svals.get("byteOffset", 0)), scount, ncomp, dtype, None,
                        what + " sparse values")
        out = out.copy()
        out[idx] = vals

    if acc.get("normalized", False):
        if ctype not in _NORMALIZE_DIVISORS:
            raise ValueError(f"{what}: normalized is only valid for integer components")
        return np.maximum(out.astype(np.float64) / _NORMALIZE_DIVISORS[ctype], -1.0)
    if ctype == 5126:
        return out.astype(np.float64)
    return out


def primitive_triangles(doc: Document, prim: dict[str, Any], vcount: int, what: str) -> np.ndarray | None:
    mode = int(prim.get("mode", 4))
    if mode not in (4, 5, 6):
        return None  # points and lines hold no surface
    if "indices" in prim:
        idx = read_accessor(doc, int(prim["indices"]))
        if idx.dtype.kind != "u" or idx.shape[1] != 1:
            raise ValueError(f"{what}: indices must be unsigned integer scalars")
        idx = idx[:, 0].astype(np.int64)
        if idx.size and (idx.max() >= vcount):
            raise ValueError(f"{what}: index {int(idx.max())} out of range (mesh has {vcount} vertices)")
    else:
        idx = np.arange(vcount, dtype=np.int64)
    if mode == 4:
        n = idx.size // 3
        return idx[: n * 3].reshape(n, 3)
    if idx.size < 3:
        return np.zeros((0, 3), dtype=np.int64)
    k = np.arange(idx.size - 2)
    if mode == 5:  # strip: alternate winding so every triangle keeps the strip's orientation
        a, b, c = idx[k], idx[k + 1], idx[k + 2]
        odd = (k % 2) == 1
        a2 = np.where(odd, b, a)
        b2 = np.where(odd, a, b)
        return np.stack([a2, b2, c], axis=1)
    return np.stack([np.full(k.size, idx[0]), idx[k + 1], idx[k + 2]], axis=1)  # fan
