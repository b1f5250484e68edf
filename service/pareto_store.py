"""Runtime Pareto store: compact format, 4-bit settings packing, octree lookup and temporal filter.

This one module is shared by the service (which writes stores) and the Blender add-on (which reads them
during playback), so it depends on the standard library and numpy only and imports no other project
module. The format is versioned JSON with numeric arrays carried as little-endian base64 blobs.

Layout of a store (power-budget paper, sec. 4.2 and 6):

- an octree over the camera path: ``root_min``/``root_size`` give the cubic root; every node is either a
  leaf (``children[n] == -1``) or has eight consecutive children starting at ``children[n]``; child ``k``
  covers the upper half along x if ``k & 1``, along y if ``k & 2``, along z if ``k & 4``;
- corners on an integer lattice of ``2**lattice_depth`` cells per root side, each with six view
  frontiers (view order :data:`VIEW_NAMES`). A view is the cube face (cone of directions around its
  axis) a camera's frustum mostly falls into; its frontier was measured at a *sample direction*: the
  axis itself (version 1, or ``view_dirs`` absent) or, since version 2, a per-(corner, view) direction
  aimed at what the path's cameras looking through that face see (``view_dirs``: int8 unit vectors,
  :func:`quantise_directions`). Since version 3 a store may instead give every *frontier* the camera
  it was measured at (``frontier_dirs``: int16 directions, ``frontier_eyes``: uint16 positions over the
  root cube, :func:`quantise_eyes`): path-sampled stores measure each face the path looks up at the
  path camera that best represents the frames looking it up, away from the corner, and the faces
  that inherit that frontier share its camera. Lookup still picks the nearest corner and the face
  with the largest frustum share; the sample camera says where that face's frontier was measured;
- frontiers: lists of (packed settings, error, power), power ascending and error descending, shared
  between corners and views that inherit them. Error and power are quantised to 16 bits (error over
  [0, 1], power over [0, ``power_scale``]); the quantisation step is reported by :meth:`ParetoStore.stats`.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

FORMAT_NAME = "render-budget/pareto-store"
FORMAT_VERSION = 3
#: Versions this reader accepts (version 1 stores have axis-aligned sample views at the corners,
#: version 2 adds sample directions, version 3 sample eyes).
READABLE_VERSIONS = (1, 2, 3)

BITS_PER_PARAM = 4
MAX_VALUES_PER_PARAM = 1 << BITS_PER_PARAM
MAX_PARAMS = 32 // BITS_PER_PARAM

#: The six axis views of a corner's view cube, in storage order.
VIEW_NAMES: tuple[str, ...] = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
#: Forward direction of each view (world frame, Z up).
VIEW_FORWARD = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64
)
#: Up vector used when rendering each view: world +Z for horizontal views, +Y when looking along Z.
VIEW_UP = np.array(
    [[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 1, 0], [0, 1, 0]], dtype=np.float64
)

_QMAX = 65535
_SIGNED_TO_VIEW = (0, 2, 4, 1, 3, 5)  # +X, +Y, +Z, -X, -Y, -Z -> VIEW_NAMES order
_DIR_Q = 127  # int8 quantisation of per-view sample directions (version 2)
_DIR_Q16 = 32767  # int16 quantisation of per-frontier sample directions (version 3, path cameras)
_EYE_Q = 65535  # uint16 quantisation of sample eyes over the root cube


def quantise_directions(directions: Any, *, fine: bool = False) -> np.ndarray:
    """Unit vectors (..., 3) rounded to the grid the store keeps (int8 per-view directions, or int16
    per-frontier ones when ``fine``: a path camera's direction to ~0.002 degrees), renormalised.

    The optimiser renders with the quantised direction so the stored sample is exactly what was
    measured."""
    d = np.asarray(directions, dtype=np.float64)
    if d.shape[-1:] != (3,) or not np.all(np.isfinite(d)):
        raise ValueError("directions must be finite (..., 3) vectors")
    q = _direction_codes(d, _DIR_Q16 if fine else _DIR_Q).astype(np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _eye_codes(eyes: Any, root_min: Any, root_size: float) -> np.ndarray:
    u = (np.asarray(eyes, dtype=np.float64) - np.asarray(root_min, dtype=np.float64)) / float(root_size)
    return np.rint(np.clip(u, 0.0, 1.0) * _EYE_Q).astype(np.uint16)


def quantise_eyes(eyes: Any, root_min: Any, root_size: float) -> np.ndarray:
    """Sample eyes as the store keeps them: uint16 steps over the root cube (clamped into it), so the
    optimiser renders exactly the camera a loaded store reports."""
    rm = np.asarray(root_min, dtype=np.float64)
    return rm + _eye_codes(eyes, rm, root_size).astype(np.float64) / _EYE_Q * float(root_size)


def _direction_codes(d: np.ndarray, q: int = _DIR_Q) -> np.ndarray:
    """Integer codes of directions: scaled so the largest component is +-q (a cube-map style code, so
    decoding and re-encoding gives the same codes); int8 for q = 127, int16 for q = 32767."""
    m = np.abs(d).max(axis=-1, keepdims=True)
    if np.any(m < 1e-300):
        raise ValueError("directions must be non-zero")
    return np.rint(d / m * q).astype(np.int8 if q <= 127 else np.int16)


def view_up(forward: Any) -> np.ndarray:
    """Up vector for rendering a sample view: world +Z, or +Y when looking (nearly) along Z."""
    f = np.asarray(forward, dtype=np.float64)
    f = f / np.linalg.norm(f)
    return np.array([0.0, 1.0, 0.0]) if abs(f[2]) > 0.95 else np.array([0.0, 0.0, 1.0])


def face_of(direction: Any) -> int:
    """View-cube face (index into :data:`VIEW_NAMES`) whose cone contains ``direction``."""
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(d)) or not np.any(d):
        raise ValueError("direction must be a finite non-zero 3-vector")
    return _SIGNED_TO_VIEW[int(np.concatenate((d, -d)).argmax())]


# ----------------------------------------------------------------------------------------------------
# 4-bit packing (the single implementation; service.params imports it)


def pack_indices(indices: Sequence[int]) -> int:
    """Pack per-parameter value indices into one 32-bit integer, 4 bits each, parameter 0 lowest."""
    if len(indices) > MAX_PARAMS:
        raise ValueError(f"at most {MAX_PARAMS} parameters fit in 32 bits, got {len(indices)}")
    packed = 0
    for i, v in enumerate(indices):
        iv = int(v)
        if iv != v or not 0 <= iv < MAX_VALUES_PER_PARAM:
            raise ValueError(f"parameter {i} index {v!r} is outside 0..{MAX_VALUES_PER_PARAM - 1}")
        packed |= iv << (BITS_PER_PARAM * i)
    return packed


def unpack_indices(packed: int, n_params: int) -> tuple[int, ...]:
    """Inverse of :func:`pack_indices`; bits above the last parameter must be zero."""
    if not 0 <= n_params <= MAX_PARAMS:
        raise ValueError(f"n_params must be in 0..{MAX_PARAMS}, got {n_params}")
    p = int(packed)
    if p != packed or p < 0 or p >> (BITS_PER_PARAM * n_params):
        raise ValueError(f"packed value {packed!r} does not fit {n_params} parameters of 4 bits")
    mask = MAX_VALUES_PER_PARAM - 1
    return tuple((p >> (BITS_PER_PARAM * i)) & mask for i in range(n_params))


def pack_array(indices: np.ndarray) -> np.ndarray:
    """Vectorised :func:`pack_indices` for an (N, P) integer array; returns uint32 (N,)."""
    a = np.asarray(indices)
    if a.ndim != 2 or a.shape[1] > MAX_PARAMS:
        raise ValueError(f"expected (N, <= {MAX_PARAMS}) indices, got shape {a.shape}")
    if a.size and (a.min() < 0 or a.max() >= MAX_VALUES_PER_PARAM):
        raise ValueError("indices must be in 0..15")
    shifts = (BITS_PER_PARAM * np.arange(a.shape[1])).astype(np.uint32)
    out = np.zeros(a.shape[0], dtype=np.uint32)
    for j in range(a.shape[1]):
        out |= a[:, j].astype(np.uint32) << shifts[j]
    return out


def unpack_array(packed: np.ndarray, n_params: int) -> np.ndarray:
    """Vectorised :func:`unpack_indices`; returns int64 (N, n_params)."""
    p = np.asarray(packed, dtype=np.uint64).reshape(-1)
    shifts = (BITS_PER_PARAM * np.arange(n_params)).astype(np.uint64)
    return ((p[:, None] >> shifts) & np.uint64(MAX_VALUES_PER_PARAM - 1)).astype(np.int64)


# ----------------------------------------------------------------------------------------------------
# Parameter description carried inside the store (enough to name settings without service.params)


@dataclass(frozen=True)
class StoredParameter:
    """Name, ordered values and the index of the maximum-quality value of one parameter."""

    name: str
    values: tuple[Any, ...]
    max_quality: int

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "values": list(self.values), "max_quality": self.max_quality}

    @staticmethod
    def from_dict(d: dict[str, Any]) -> StoredParameter:
        values = tuple(_freeze(v) for v in d["values"])
        mq = int(d["max_quality"])
        if not values or not 0 <= mq < len(values):
            raise ValueError(f"parameter {d.get('name')!r}: bad values or max_quality")
        return StoredParameter(str(d["name"]), values, mq)


def _freeze(v: Any) -> Any:
    if isinstance(v, list):
        return tuple(_freeze(x) for x in v)
    if isinstance(v, dict):
        return tuple(sorted((k, _freeze(x)) for k, x in v.items()))
    return v


def _thaw(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_thaw(x) for x in v]
    return v


# ----------------------------------------------------------------------------------------------------
# Frontier


@dataclass(frozen=True)
class Frontier:
    """A Pareto frontier: packed settings with error and power, power ascending, error descending."""

    packed: np.ndarray  # uint32 (N,)
    error: np.ndarray  # float64 (N,)
    power_w: np.ndarray  # float64 (N,)

    @staticmethod
    def from_points(packed: Iterable[int], error: Iterable[float], power_w: Iterable[float]) -> Frontier:
        """Keep the non-dominated points (ties: first occurrence) and sort them by power."""
        pk = np.asarray(list(packed), dtype=np.uint32)
        e = np.asarray(list(error), dtype=np.float64)
        p = np.asarray(list(power_w), dtype=np.float64)
        if not (pk.shape == e.shape == p.shape) or pk.ndim != 1 or pk.size == 0:
            raise ValueError("a frontier needs equally long, non-empty packed/error/power lists")
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(p))):
            raise ValueError("frontier error and power must be finite")
        order = np.lexsort((e, p))  # by power, then error
        keep: list[int] = []
        best_e = math.inf
        for i in order:
            if e[i] < best_e:
                keep.append(int(i))
                best_e = e[i]
        k = np.asarray(keep, dtype=np.int64)
        return Frontier(pk[k], e[k], p[k])

    def __len__(self) -> int:
        return int(self.packed.size)

    def under_power(self, budget: float) -> tuple[int, bool]:
        """Index of the least error with power <= budget; (cheapest, True) when none fits."""
        i = int(np.searchsorted(self.power_w, budget, side="right")) - 1
        return (0, True) if i < 0 else (i, False)

    def under_error(self, budget: float) -> tuple[int, bool]:
        """Index of the least power with error <= budget; (most accurate, True) when none fits."""
        # error is descending: search on the negated (ascending) array
        i = int(np.searchsorted(-self.error, -budget, side="left"))
        return (len(self) - 1, True) if i >= len(self) else (i, False)


# ----------------------------------------------------------------------------------------------------
# Base64 array helpers


def _enc(arr: np.ndarray, dtype: str) -> str:
    a = np.ascontiguousarray(np.asarray(arr).astype(dtype, copy=False))
    return f"{dtype}:" + base64.b64encode(a.tobytes()).decode("ascii")


def _dec(text: str) -> np.ndarray:
    dtype, _, data = str(text).partition(":")
    if dtype not in ("<i1", "<u1", "<i2", "<u2", "<u4", "<i4", "<f4", "<f8"):
        raise ValueError(f"unsupported array dtype {dtype!r} in store")
    try:
        raw = base64.b64decode(data.encode("ascii"), validate=True)
    except ValueError as exc:
        raise ValueError(f"corrupt base64 array in store: {exc}") from exc
    if len(raw) % np.dtype(dtype).itemsize:
        raise ValueError("corrupt array length in store")
    return np.frombuffer(raw, dtype=dtype)


def _uint_dtype(max_value: int) -> str:
    return "<u1" if max_value < 256 else "<u2" if max_value < 65536 else "<u4"


# ----------------------------------------------------------------------------------------------------
# Lookup result and the store


@dataclass(frozen=True)
class LookupResult:
    """Settings chosen for one camera and budget, with their predicted error and power and flags."""

    indices: tuple[int, ...]
    packed: int
    settings: dict[str, Any]
    power_w: float
    error: float
    clamped: bool
    infeasible: bool
    corner: int = -1
    view: int = -1
    leaf: int = -1


def _vec3_floats(v: Any, name: str) -> tuple[float, float, float]:
    """Three finite floats from a sequence or array (fast path for the per-frame lookup)."""
    try:
        if len(v) != 3:
            raise ValueError
        a, b, c = float(v[0]), float(v[1]), float(v[2])
    except (TypeError, ValueError, IndexError) as exc:
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}") from exc
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a, b, c


def _finite_vec3(v: Any, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a


@dataclass
class ParetoStore:
    """Octree of camera samples with one Pareto frontier per (corner, view); see the module docstring."""

    parameters: tuple[StoredParameter, ...]
    root_min: np.ndarray
    root_size: float
    lattice_depth: int
    children: np.ndarray  # int32 (n_nodes,)
    corner_coords: np.ndarray  # int64 (C, 3) lattice coordinates
    corner_views: np.ndarray  # int64 (C, 6) frontier ids
    frontiers: list[Frontier]
    vfov: float = 0.6911
    aspect: float = 16 / 9
    profile: str = "mobile"
    fps: float = 30.0
    meta: dict[str, Any] = field(default_factory=dict)
    view_dirs: np.ndarray | None = None  # float64 (C, 6, 3) sample directions; None = the axes
    frontier_dirs: np.ndarray | None = None  # float64 (F, 3) sample direction of each frontier
    frontier_eyes: np.ndarray | None = None  # float64 (F, 3) sample eye of each frontier

    def __post_init__(self) -> None:
        self.root_min = _finite_vec3(self.root_min, "root_min")
        self.root_size = float(self.root_size)
        if not (math.isfinite(self.root_size) and self.root_size > 0):
            raise ValueError("root_size must be positive and finite")
        if not 0 <= self.lattice_depth <= 16:
            raise ValueError("lattice_depth must be in 0..16")
        self.children = np.asarray(self.children, dtype=np.int64).reshape(-1)
        self.corner_coords = np.asarray(self.corner_coords, dtype=np.int64).reshape(-1, 3)
        self.corner_views = np.asarray(self.corner_views, dtype=np.int64).reshape(-1, 6)
        n_nodes = self.children.size
        if n_nodes == 0:
            raise ValueError("a store needs at least the root node")
        ch = self.children
        if np.any((ch != -1) & ((ch <= 0) | (ch + 8 > n_nodes))):
            raise ValueError("children index out of range")
        if self.corner_coords.shape[0] != self.corner_views.shape[0]:
            raise ValueError("corner_coords and corner_views disagree on the corner count")
        side = 1 << self.lattice_depth
        if self.corner_coords.size and (self.corner_coords.min() < 0 or self.corner_coords.max() > side):
            raise ValueError("corner lattice coordinates out of range")
        if self.corner_views.size and (
            self.corner_views.min() < 0 or self.corner_views.max() >= len(self.frontiers)
        ):
            raise ValueError("corner view refers to a missing frontier")
        if self.view_dirs is not None:
            vd = np.asarray(self.view_dirs, dtype=np.float64)
            if vd.shape != (self.corner_coords.shape[0], 6, 3) or not np.all(np.isfinite(vd)):
                raise ValueError("view_dirs must be finite (corners, 6, 3)")
            n = np.linalg.norm(vd, axis=2, keepdims=True)
            if np.any(n < 1e-9):
                raise ValueError("view_dirs must be non-zero")
            self.view_dirs = vd / n
        if (self.frontier_dirs is None) != (self.frontier_eyes is None):
            raise ValueError("frontier_dirs and frontier_eyes come together")
        if self.frontier_dirs is not None:
            fd = np.asarray(self.frontier_dirs, dtype=np.float64)
            fe = np.asarray(self.frontier_eyes, dtype=np.float64)
            nf = len(self.frontiers)
            if fd.shape != (nf, 3) or fe.shape != (nf, 3) or not (np.all(np.isfinite(fd))
                                                                   and np.all(np.isfinite(fe))):
                raise ValueError("frontier_dirs and frontier_eyes must be finite (frontiers, 3)")
            n = np.linalg.norm(fd, axis=1, keepdims=True)
            if np.any(n < 1e-9):
                raise ValueError("frontier_dirs must be non-zero")
            self.frontier_dirs = fd / n
            self.frontier_eyes = fe
        if len(self.parameters) > MAX_PARAMS:
            raise ValueError(f"at most {MAX_PARAMS} parameters")
        for prm in self.parameters:
            if len(prm.values) > MAX_VALUES_PER_PARAM:
                raise ValueError(f"parameter {prm.name!r} has more than 16 values")
        self._index()

    # -- derived tables ---------------------------------------------------------------------------

    def _index(self) -> None:
        """Precompute each leaf's eight corner ids so lookups are a short descent and table reads."""
        key = {tuple(int(c) for c in xyz): i for i, xyz in enumerate(self.corner_coords)}
        side = 1 << self.lattice_depth
        self._leaf_corners: dict[int, np.ndarray] = {}
        self._node_origin: dict[int, tuple[int, int, int, int]] = {}
        stack = [(0, 0, 0, 0, side)]
        while stack:
            node, x, y, z, s = stack.pop()
            self._node_origin[node] = (x, y, z, s)
            c = int(self.children[node])
            if c == -1:
                ids = []
                for k in range(8):
                    xyz = (x + s * (k & 1), y + s * ((k >> 1) & 1), z + s * ((k >> 2) & 1))
                    if xyz not in key:
                        raise ValueError(f"leaf {node} misses its corner at lattice {xyz}")
                    ids.append(key[xyz])
                self._leaf_corners[node] = np.asarray(ids, dtype=np.int64)
            else:
                if s < 2:
                    raise ValueError("octree deeper than the lattice")
                h = s // 2
                for k in range(8):
                    stack.append((c + k, x + h * (k & 1), y + h * ((k >> 1) & 1), z + h * ((k >> 2) & 1), h))
        self._frustum_cache: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}
        cell = self.root_size / side
        self._lo = tuple(float(c) for c in self.root_min)
        self._hi = tuple(float(c) + self.root_size for c in self.root_min)
        self._lattice_scale = side / self.root_size
        self._children_list = [int(c) for c in self.children]
        self._leaf_box: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._leaf_corner_pos: dict[int, list[tuple[int, tuple[float, float, float]]]] = {}
        for leaf, ids in self._leaf_corners.items():
            x, y, z, s = self._node_origin[leaf]
            lo = self.root_min + np.array([x, y, z], dtype=np.float64) * cell
            self._leaf_box[leaf] = (lo, lo + s * cell)
            self._leaf_corner_pos[leaf] = [
                (int(c), tuple(float(v) for v in self.root_min + self.corner_coords[c] * cell))  # type: ignore[misc]
                for c in ids]

    @property
    def n_params(self) -> int:
        return len(self.parameters)

    def corner_positions(self) -> np.ndarray:
        """World positions (C, 3) of the corners."""
        cell = self.root_size / (1 << self.lattice_depth)
        return self.root_min[None, :] + self.corner_coords.astype(np.float64) * cell

    def sample_direction(self, corner: int, view: int) -> np.ndarray:
        """Unit direction (world) at which the (corner, view) frontier was measured."""
        if self.frontier_dirs is not None:
            return self.frontier_dirs[int(self.corner_views[int(corner), int(view)])].copy()
        if self.view_dirs is None:
            return VIEW_FORWARD[int(view)].copy()
        return self.view_dirs[int(corner), int(view)].copy()

    def sample_camera(self, corner: int, view: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(eye, forward, up) of the camera sample behind the (corner, view) frontier."""
        f = self.sample_direction(corner, view)
        if self.frontier_eyes is not None:
            return self.frontier_eyes[int(self.corner_views[int(corner), int(view)])].copy(), f, view_up(f)
        up = VIEW_UP[int(view)].copy() if self.view_dirs is None else view_up(f)
        return self.corner_positions()[int(corner)], f, up

    def frontier(self, corner: int, view: int) -> Frontier:
        return self.frontiers[int(self.corner_views[corner, view])]

    def leaf_depths(self) -> dict[int, int]:
        """Depth of every leaf (root = 0)."""
        side = 1 << self.lattice_depth
        return {n: round(math.log2(side / o[3])) for n, o in self._node_origin.items()
                if self.children[n] == -1}

    # -- lookup -----------------------------------------------------------------------------------

    def find_leaf(self, position: Any) -> tuple[int, np.ndarray, bool]:
        """Leaf containing ``position`` (clamped into the root); returns (leaf, clamped position, clamped)."""
        p = _vec3_floats(position, "position")
        lo = self._lo
        hi = self._hi
        q = tuple(min(max(p[i], lo[i]), hi[i]) for i in range(3))
        clamped = q != p
        k_scale = self._lattice_scale
        u = [(q[i] - lo[i]) * k_scale for i in range(3)]
        node = 0
        x = y = z = 0
        s = 1 << self.lattice_depth
        children = self._children_list
        while children[node] != -1:
            h = s // 2
            k = int(u[0] >= x + h) | (int(u[1] >= y + h) << 1) | (int(u[2] >= z + h) << 2)
            x += h * (k & 1)
            y += h * ((k >> 1) & 1)
            z += h * ((k >> 2) & 1)
            s = h
            node = children[node] + k
        return node, np.asarray(q), clamped

    def _frustum_rays(self, vfov: float, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        key = (round(vfov, 6), round(aspect, 6))
        rays = self._frustum_cache.get(key)
        if rays is None:
            n = 8
            th = math.tan(vfov / 2)
            v = (np.arange(n) + 0.5) / n * 2 - 1
            uu, vv = np.meshgrid(v * th * aspect, v * th)
            # camera frame: x right, y up, looking down -z; weight = pixel solid angle on the image plane
            d = np.stack([uu.ravel(), vv.ravel(), -np.ones(n * n)])
            w = 1.0 / np.linalg.norm(d, axis=0) ** 3
            rays = (np.ascontiguousarray(d), w)
            if len(self._frustum_cache) > 64:
                self._frustum_cache.clear()
            self._frustum_cache[key] = rays
        return rays

    def choose_view(self, rotation: np.ndarray, vfov: float, aspect: float) -> int:
        """View-cube face that receives the largest (solid-angle weighted) part of the camera frustum.

        The view cube is a cube map around the camera, like the six axis views stored at each corner:
        a frustum ray lands on the face of its largest direction component."""
        rays_t, weights = self._frustum_rays(vfov, aspect)
        d = np.asarray(rotation) @ rays_t  # (3, N) world directions
        # scores in the order +X, +Y, +Z, -X, -Y, -Z; the largest is the face a ray lands on
        face = np.concatenate((d, -d)).argmax(axis=0)
        return _SIGNED_TO_VIEW[int(np.bincount(face, weights=weights, minlength=6).argmax())]

    def _locate(self, position: Any, rotation: np.ndarray, vfov: float, aspect: float
                ) -> tuple[int, int, int, bool]:
        """(leaf, corner, view, clamped) a camera looks up: nearest corner of its leaf, then the face."""
        leaf, q, clamped = self.find_leaf(position)
        qx, qy, qz = float(q[0]), float(q[1]), float(q[2])
        best = math.inf
        corner = -1
        for c, (cx, cy, cz) in self._leaf_corner_pos[leaf]:
            dd = (cx - qx) ** 2 + (cy - qy) ** 2 + (cz - qz) ** 2
            if dd < best:
                best, corner = dd, c
        return leaf, corner, self.choose_view(rotation, vfov, aspect), clamped

    def locate(self, position: Any, direction: Any = None, matrix: Any = None, fov: float | None = None,
               aspect: float | None = None, up: Any = None) -> tuple[int, int]:
        """(corner, view) whose frontier :meth:`lookup` would read for this camera (no budget needed);
        the optimiser uses it to group path frames by the sample that will serve them."""
        rot = camera_rotation(direction, matrix, up)
        vf = self.vfov if fov is None else float(fov)
        asp = self.aspect if aspect is None else float(aspect)
        _, corner, view, _ = self._locate(position, rot, vf, asp)
        return corner, view

    def lookup(self, position: Any, direction: Any = None, matrix: Any = None, fov: float | None = None,
               power_budget: float | None = None, error_budget: float | None = None,
               aspect: float | None = None, up: Any = None) -> LookupResult:
        """Settings for a camera at ``position`` looking along ``direction`` (or oriented by ``matrix``,
        Blender's 4x4 camera world matrix) with vertical field of view ``fov`` in radians, under exactly
        one of ``power_budget`` (W) or ``error_budget`` (1 - SSIM)."""
        if (power_budget is None) == (error_budget is None):
            raise ValueError("give exactly one of power_budget or error_budget")
        budget = float(power_budget if power_budget is not None else error_budget)  # type: ignore[arg-type]
        if not math.isfinite(budget):
            raise ValueError("budget must be finite")
        rot = camera_rotation(direction, matrix, up)
        vf = self.vfov if fov is None else float(fov)
        if not (math.isfinite(vf) and 0 < vf < math.pi):
            raise ValueError(f"fov must be in (0, pi) radians, got {fov!r}")
        asp = self.aspect if aspect is None else float(aspect)
        if not (math.isfinite(asp) and asp > 0):
            raise ValueError("aspect must be positive")
        leaf, corner, view, clamped = self._locate(position, rot, vf, asp)
        fr = self.frontier(corner, view)
        if power_budget is not None:
            i, infeasible = fr.under_power(budget)
        else:
            i, infeasible = fr.under_error(budget)
        packed = int(fr.packed[i])
        indices = unpack_indices(packed, self.n_params)
        return LookupResult(indices, packed, self.settings_of(indices), float(fr.power_w[i]),
                            float(fr.error[i]), clamped, infeasible, corner, view, leaf)

    def corner_positions_of(self, corners: np.ndarray) -> np.ndarray:
        cell = self.root_size / (1 << self.lattice_depth)
        return self.root_min[None, :] + self.corner_coords[corners].astype(np.float64) * cell

    def settings_of(self, indices: Sequence[int]) -> dict[str, Any]:
        """Parameter name -> value for value indices (JSON-friendly values)."""
        return {p.name: _thaw(p.values[i]) for p, i in zip(self.parameters, indices, strict=True)}

    # -- serialisation ----------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The versioned JSON document (see module docstring)."""
        all_packed = np.concatenate([f.packed for f in self.frontiers]) if self.frontiers else np.zeros(0)
        table, inverse = np.unique(all_packed.astype(np.uint32), return_inverse=True)
        sizes = np.asarray([len(f) for f in self.frontiers], dtype=np.int64)
        err = np.concatenate([f.error for f in self.frontiers]) if self.frontiers else np.zeros(0)
        pw = np.concatenate([f.power_w for f in self.frontiers]) if self.frontiers else np.zeros(0)
        if err.size and (err.min() < 0 or err.max() > 1):
            raise ValueError("frontier errors must lie in [0, 1] to be stored")
        if pw.size and pw.min() < 0:
            raise ValueError("frontier power must be non-negative to be stored")
        power_scale = float(pw.max()) if pw.size and pw.max() > 0 else 1.0
        eq = np.rint(err * _QMAX).astype(np.int64)
        pq = np.rint(pw / power_scale * _QMAX).astype(np.int64)
        side = 1 << self.lattice_depth
        extra = {}
        if self.view_dirs is not None:
            extra["view_dirs"] = _enc(_direction_codes(self.view_dirs).reshape(-1), "<i1")
        if self.frontier_dirs is not None and self.frontier_eyes is not None:
            extra["frontier_dirs"] = _enc(_direction_codes(self.frontier_dirs, _DIR_Q16).reshape(-1), "<i2")
            extra["frontier_eyes"] = _enc(_eye_codes(self.frontier_eyes, self.root_min,
                                                     self.root_size).reshape(-1), "<u2")
        return {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "profile": self.profile,
            "fps": self.fps,
            "vfov": self.vfov,
            "aspect": self.aspect,
            "views": list(VIEW_NAMES),
            "parameters": [p.to_dict() for p in self.parameters],
            "root_min": [float(c) for c in self.root_min],
            "root_size": self.root_size,
            "lattice_depth": self.lattice_depth,
            "children": _enc(self.children, "<i4"),
            "corners": _enc(self.corner_coords, _uint_dtype(side)),
            "corner_views": _enc(self.corner_views, _uint_dtype(max(len(self.frontiers), 1))),
            "settings": _enc(table, "<u4"),
            "frontier_sizes": _enc(sizes, _uint_dtype(int(sizes.max()) if sizes.size else 0)),
            "frontier_settings": _enc(inverse, _uint_dtype(max(table.size, 1))),
            "frontier_error": _enc(eq, "<u2"),
            "frontier_power": _enc(pq, "<u2"),
            "power_scale": power_scale,
            "meta": self.meta,
            **extra,
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), separators=(",", ":"), allow_nan=False)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> ParetoStore:
        if not isinstance(d, dict) or d.get("format") != FORMAT_NAME:
            raise ValueError("not a render-budget Pareto store")
        if d.get("version") not in READABLE_VERSIONS:
            raise ValueError(f"unsupported store version {d.get('version')!r} (reader: {READABLE_VERSIONS})")
        try:
            params = tuple(StoredParameter.from_dict(p) for p in d["parameters"])
            sizes = _dec(d["frontier_sizes"]).astype(np.int64)
            table = _dec(d["settings"]).astype(np.uint32)
            idx = _dec(d["frontier_settings"]).astype(np.int64)
            eq = _dec(d["frontier_error"]).astype(np.float64) / _QMAX
            pq = _dec(d["frontier_power"]).astype(np.float64) / _QMAX * float(d["power_scale"])
            if not (idx.size == eq.size == pq.size == int(sizes.sum())):
                raise ValueError("frontier arrays disagree in length")
            if idx.size and idx.max() >= table.size:
                raise ValueError("frontier refers to a missing settings entry")
            frontiers = []
            off = 0
            for n in sizes:
                sl = slice(off, off + int(n))
                frontiers.append(Frontier(table[idx[sl]], eq[sl], pq[sl]))
                off += int(n)
            view_dirs = None
            if d.get("version", 1) >= 2 and d.get("view_dirs") is not None:
                vq = _dec(d["view_dirs"]).astype(np.float64)
                if vq.size % 18:
                    raise ValueError("view_dirs length is not a multiple of 6 x 3")
                view_dirs = vq.reshape(-1, 6, 3)
            frontier_dirs = frontier_eyes = None
            if d.get("version", 1) >= 3 and d.get("frontier_dirs") is not None:
                frontier_dirs = _dec(d["frontier_dirs"]).astype(np.float64).reshape(-1, 3)
                frontier_eyes = (np.asarray(d["root_min"], dtype=np.float64)
                                 + _dec(d["frontier_eyes"]).astype(np.float64).reshape(-1, 3) / _EYE_Q
                                 * float(d["root_size"]))
            return ParetoStore(
                parameters=params,
                root_min=np.asarray(d["root_min"], dtype=np.float64),
                root_size=float(d["root_size"]),
                lattice_depth=int(d["lattice_depth"]),
                children=_dec(d["children"]),
                corner_coords=_dec(d["corners"]),
                corner_views=_dec(d["corner_views"]),
                frontiers=frontiers,
                vfov=float(d["vfov"]),
                aspect=float(d["aspect"]),
                profile=str(d["profile"]),
                fps=float(d["fps"]),
                meta=dict(d.get("meta") or {}),
                view_dirs=view_dirs,
                frontier_dirs=frontier_dirs,
                frontier_eyes=frontier_eyes,
            )
        except (KeyError, TypeError) as exc:
            raise ValueError(f"malformed store: missing or wrong field {exc}") from exc

    @staticmethod
    def from_json(text: str | bytes) -> ParetoStore:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"store is not valid JSON: {exc}") from exc
        return ParetoStore.from_dict(d)

    def stats(self) -> dict[str, Any]:
        """Sizes and counts worth reporting (bytes of the JSON, nodes, corners, views, points)."""
        depths = self.leaf_depths()
        return {
            "size_bytes": len(self.to_json().encode()),
            "nodes": int(self.children.size),
            "leaves": len(depths),
            "depth": max(depths.values()) if depths else 0,
            "corners": int(self.corner_coords.shape[0]),
            "views": int(self.corner_coords.shape[0] * 6),
            "unique_frontiers": len(self.frontiers),
            "frontier_points": int(sum(len(f) for f in self.frontiers)),
            "error_step": 1.0 / _QMAX,
            "power_step_w": (max((float(f.power_w.max()) for f in self.frontiers), default=1.0)) / _QMAX,
        }


def root_cube(positions: Any, pad_fraction: float = 0.1, min_size: float = 1.0, *,
              rest_on_path: bool = False) -> tuple[np.ndarray, float]:
    """Cubic root box around camera positions: the bounding box, padded by ``pad_fraction`` of its
    largest side on every side, made cubic about its centre; at least ``min_size`` wide so that
    degenerate paths (one point, a line, a plane) still get a proper cube. Returns (min corner, side).

    ``rest_on_path`` lifts the cube so its bottom lies below the path's lowest point by
    ``pad_fraction`` of the path's *vertical* extent instead of centring it vertically: for a flat
    path (a walk or an orbit above a floor) the lower corners then stay near camera height rather
    than far below the ground."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if p.shape[0] == 0 or not np.all(np.isfinite(p)):
        raise ValueError("need at least one finite position")
    if not (pad_fraction >= 0 and min_size > 0):
        raise ValueError("pad_fraction must be >= 0 and min_size > 0")
    lo, hi = p.min(axis=0), p.max(axis=0)
    extent = float((hi - lo).max())
    size = max(extent * (1.0 + 2.0 * pad_fraction), float(min_size))
    centre = (lo + hi) / 2
    root_min = centre - size / 2
    if rest_on_path:
        root_min[2] = max(root_min[2], lo[2] - pad_fraction * float(hi[2] - lo[2]))
    return root_min, size


def _scale_free(v: tuple[float, float, float], name: str) -> tuple[float, float, float]:
    """Divide by the largest component (so squaring cannot overflow); zero vectors are refused."""
    m = max(abs(v[0]), abs(v[1]), abs(v[2]))
    if m == 0.0 or m < 1e-300:
        raise ValueError(f"{name} must be non-zero")
    return v[0] / m, v[1] / m, v[2] / m


def camera_rotation(direction: Any = None, matrix: Any = None, up: Any = None) -> np.ndarray:
    """3x3 camera-to-world rotation (columns: right, up, backward; the camera looks down local -Z).

    From Blender's 4x4 (or 3x3) ``matrix_world``, or from a view ``direction`` with ``up`` (default
    world +Z, or +Y when looking straight along Z)."""
    if (direction is None) == (matrix is None):
        raise ValueError("give exactly one of direction or matrix")
    if matrix is not None:
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape not in ((4, 4), (3, 3)) or not np.all(np.isfinite(m)):
            raise ValueError("matrix must be a finite 4x4 or 3x3 array")
        r = m[:3, :3]
        big = np.abs(r).max(axis=0)
        if np.any(big == 0):
            raise ValueError("matrix has a degenerate rotation")
        r = r / big  # scale-free first: huge but finite entries must not overflow the norms
        norms = np.linalg.norm(r, axis=0)
        if np.any(norms < 1e-12) or not np.all(np.isfinite(r)):
            raise ValueError("matrix has a degenerate rotation")
        return r / norms  # remove scale
    fx, fy, fz = _scale_free(_vec3_floats(direction, "direction"), "direction")
    n = math.sqrt(fx * fx + fy * fy + fz * fz)
    fx, fy, fz = fx / n, fy / n, fz / n
    ux, uy, uz = (0.0, 0.0, 1.0) if up is None else _scale_free(_vec3_floats(up, "up"), "up")

    def cross(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
        return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])

    r = cross((fx, fy, fz), (ux, uy, uz))
    rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    un = math.sqrt(ux * ux + uy * uy + uz * uz)
    if rn < 1e-3 * max(un, 1e-300):
        if up is not None:
            raise ValueError("up must not be parallel to direction")
        r = cross((fx, fy, fz), (0.0, 1.0, 0.0))
        rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    r = (r[0] / rn, r[1] / rn, r[2] / rn)
    tu = cross(r, (fx, fy, fz))
    return np.array([[r[0], tu[0], -fx], [r[1], tu[1], -fy], [r[2], tu[2], -fz]])


class TemporalFilter:
    """Eq. 8 of the power-budget paper: blend parameter indices from the old settings to a new target.

    ``s = round((1 - t/T) * s_old + (t/T) * s_new)`` per parameter, with ``t`` the time since the target
    changed; after ``T`` (``period_s``) the target holds. A target change in the middle of a transition
    starts the next transition from the settings shown at that moment. Time going backwards (scrubbing
    the timeline) snaps to the target; ``period_s = 0`` disables filtering.
    """

    def __init__(self, period_s: float = 2.0) -> None:
        if not (math.isfinite(period_s) and period_s >= 0):
            raise ValueError("period_s must be finite and >= 0")
        self.period_s = float(period_s)
        self.reset()

    def reset(self) -> None:
        self._old: tuple[int, ...] | None = None
        self._target: tuple[int, ...] | None = None
        self._t0 = 0.0
        self._last_t = -math.inf

    def _blend(self, now_s: float) -> tuple[int, ...]:
        assert self._target is not None
        if self._old is None or self.period_s == 0:
            return self._target
        a = (now_s - self._t0) / self.period_s
        if a >= 1.0:
            return self._target
        return tuple(math.floor((1.0 - a) * o + a * n + 0.5) for o, n in zip(self._old, self._target,
                                                                                strict=True))

    def update(self, target_indices: Sequence[int], now_s: float) -> tuple[int, ...]:
        """Settings to use at time ``now_s`` (seconds) given the current target indices."""
        now = float(now_s)
        if not math.isfinite(now):
            raise ValueError("now_s must be finite")
        target = tuple(int(v) for v in target_indices)
        if any(v < 0 for v in target):
            raise ValueError("indices must be non-negative")
        if self._target is None or now < self._last_t:
            self._old, self._target, self._t0 = None, target, now
        elif target != self._target:
            if len(target) != len(self._target):
                raise ValueError("target changed its number of parameters")
            shown = self._blend(now)
            self._old, self._target, self._t0 = shown, target, now
        self._last_t = now
        return self._blend(now)
