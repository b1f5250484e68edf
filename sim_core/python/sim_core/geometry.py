"""Mesh geometry helpers shared by the scene builder and the loaders (pure numpy)."""

from __future__ import annotations

import numpy as np


def smooth_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted per-vertex normals, float32, for meshes (or corners) that come without normals.

    A vertex whose summed face normal has zero length (no triangle uses it, or its faces cancel or are
    degenerate) gets the zero vector: the tracer then shades each of its triangles with the triangle's
    own geometric normal, which is right whatever way the surface faces (a fixed fallback such as +Z is
    wrong for every surface that does not face up).
    """
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    fn = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    vn = np.zeros_like(p)
    for k in range(3):
        np.add.at(vn, t[:, k], fn)
    length = np.linalg.norm(vn, axis=1, keepdims=True)
    vn = np.divide(vn, length, out=np.zeros_like(vn), where=length > 0)
    return vn.astype(np.float32)
