"""Meshes: Blender's per-corner mesh as per-vertex arrays (read once per evaluated mesh) and each
instance's world-space copy (the native core has no mesh instancing)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


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
