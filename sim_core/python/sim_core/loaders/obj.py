"""Wavefront OBJ loader (pure Python + numpy) for the bundled test meshes and simple exports.

Reads ``v``, ``vn``, ``f`` (any polygon, fan-triangulated; ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``;
negative indices), ``o``/``g`` (each starts a new object id), ``usemtl`` and ``mtllib`` (Kd, Ke, Ni, d/Tr,
Ns, and the PBR extension Pr/Pm). OBJ files are Y-up by convention; like Blender's importer (forward -Z,
up Y) the loader converts to the project's Z-up frame, ``(x, y, z) -> (x, -z, y)``, unless
``up_axis="Z"`` says the file already is Z-up.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Literal

import numpy as np

from ..geometry import smooth_normals
from ..scene_data import Material, SceneData
from .confined import confined_path

_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _floats(parts: list[str], n: int, what: str, lineno: int, path: Path) -> list[float]:
    try:
        vals = [float(x) for x in parts[:n]]
    except ValueError:
        raise ValueError(f"{path}:{lineno}: malformed {what} line") from None
    if len(vals) < n:
        raise ValueError(f"{path}:{lineno}: {what} needs {n} numbers")
    return vals


def _parse_mtl(path: Path) -> dict[str, Material]:
    """Materials of an MTL file; Blender's OBJ importer mapping (roughness = 1 - sqrt(Ns / 1000))."""
    out: dict[str, Material] = {}
    if not path.is_file():
        raise FileNotFoundError(f"material library {path.name!r} not found next to the OBJ file")
    current: str | None = None
    props: dict[str, object] = {}

    def flush() -> None:
        if current is None:
            return
        ns = float(props.get("Ns", 250.0))  # type: ignore[arg-type]
        rough = float(props.get("Pr", 1.0 - math.sqrt(min(max(ns, 0.0), 1000.0) / 1000.0)))  # type: ignore[arg-type]
        d = float(props.get("d", 1.0))  # type: ignore[arg-type]
        out[current] = Material(
            base_color=tuple(float(np.clip(c, 0, 1)) for c in props.get("Kd", (0.8, 0.8, 0.8))),  # type: ignore[attr-defined]
            metallic=float(np.clip(float(props.get("Pm", 0.0)), 0.0, 1.0)),  # type: ignore[arg-type]
            roughness=float(np.clip(rough, 0.0, 1.0)),
            transmission=float(np.clip(1.0 - d, 0.0, 1.0)),
            ior=float(np.clip(float(props.get("Ni", 1.5)), 1.0, 4.0)),  # type: ignore[arg-type]
            emission=tuple(props.get("Ke", (0.0, 0.0, 0.0))),  # type: ignore[arg-type]
            name=current,
        )

    for lineno, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        key, args = parts[0], parts[1:]
        if key == "newmtl":
            flush()
            current, props = " ".join(args), {}
        elif key in ("Kd", "Ke"):
            props[key] = tuple(_floats(args, 3, key, lineno, path))
        elif key in ("Ns", "Ni", "d", "Pr", "Pm"):
            props[key] = _floats(args, 1, key, lineno, path)[0]
        elif key == "Tr":
            props["d"] = 1.0 - _floats(args, 1, key, lineno, path)[0]
    flush()
    return out


def _parse_simple(lines: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """Vectorised parse of the common plain file (only 'v x y z' and 'f a b c' with positive indices, no
    objects, groups or materials): the bundled scans load ~20x faster. None means "use the general
    parser", which also reports errors with line numbers."""
    # First characters allowed: comments, v/vt/vn (unused without '/'), f, s (smoothing groups).
    if any(line and line[0] not in "#vfs" for line in lines):
        return None
    if any(line[:2] in ("f\t", "v\t") for line in lines):
        return None
    v_lines = [line[2:] for line in lines if line[:2] == "v "]
    f_lines = [line[2:] for line in lines if line[:2] == "f "]
    if not v_lines or not f_lines:
        return None
    faces_text = " ".join(f_lines)
    if "/" in faces_text:
        return None
    try:
        verts = np.array(" ".join(v_lines).split(), dtype=np.float64)
        idx = np.array(faces_text.split(), dtype=np.int64)
    except ValueError:
        return None
    if verts.size != 3 * len(v_lines) or idx.size != 3 * len(f_lines):
        return None  # 'w' components, colours or polygons: the general parser handles them
    if idx.min() <= 0 or idx.max() > len(v_lines):
        return None
    return verts.reshape(-1, 3), idx.reshape(-1, 3) - 1


def load_obj(path: str | os.PathLike[str], *, up_axis: Literal["Y", "Z"] = "Y") -> SceneData:
    """Load an OBJ into flat arrays in the project's Z-up world frame.

    Per-vertex normals are kept when the file gives them (vertices are split where a position carries
    different normals). Raises FileNotFoundError / ValueError on missing or malformed files, NaN/Inf
    coordinates, out-of-range indices and files without a single triangle.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"OBJ file not found: {p}")
    if up_axis not in ("Y", "Z"):
        raise ValueError(f"up_axis must be 'Y' or 'Z', got {up_axis!r}")
    try:
        text = p.read_text()
    except UnicodeDecodeError:
        raise ValueError(f"{p}: not a text OBJ file") from None

    lines = text.splitlines()
    simple = _parse_simple(lines)
    if simple is not None:
        return _simple_scene(p, *simple, up_axis)
    parser = _Parser(p)
    parser.parse(lines)
    return parser.scene_data(up_axis)


def _simple_scene(p: Path, positions: np.ndarray, tris: np.ndarray, up_axis: str) -> SceneData:
    """The scene of a plain file (:func:`_parse_simple`): one object, one default material."""
    if not np.all(np.isfinite(positions)):
        raise ValueError(f"{p}: vertex positions contain NaN or Inf")
    if up_axis == "Y":
        positions = positions @ _Y_TO_Z.T
    return SceneData(
        positions=positions.astype(np.float32),
        triangles=tris.astype(np.uint32),
        material_ids=np.zeros(tris.shape[0], dtype=np.uint32),
        object_ids=np.zeros(tris.shape[0], dtype=np.uint32),
        materials=[Material(name="default")],
        source=str(p),
        object_names=[p.stem],
    )


class _Parser:
    """The general parser: one pass over the lines, keeping the running face, object and material state."""

    def __init__(self, p: Path) -> None:
        self.p = p
        self.verts: list[list[float]] = []
        self.vnormals: list[list[float]] = []
        self.corners_v: list[int] = []  # triangle corners: position index (0-based)
        self.corners_n: list[int] = []  # normal index or -1
        self.tri_mat: list[int] = []
        self.tri_obj: list[int] = []
        self.materials: list[Material] = []
        self.mat_index: dict[str, int] = {}
        self.library: dict[str, Material] = {}
        self.current_mat = -1
        self.object_names: list[str] = []
        self.current_obj = -1

    def parse(self, lines: list[str]) -> None:
        p = self.p
        for lineno, line in enumerate(lines, 1):
            if not line or line[0] == "#":
                continue
            parts = line.split()
            if not parts:
                continue
            key = parts[0]
            if key == "v":
                self.verts.append(_floats(parts[1:], 3, "v", lineno, p))
            elif key == "vn":
                self.vnormals.append(_floats(parts[1:], 3, "vn", lineno, p))
            elif key == "f":
                self._face(parts, line, lineno)
            elif key in ("o", "g"):
                name = " ".join(parts[1:]) or f"object_{len(self.object_names)}"
                self.current_obj = len(self.object_names)
                self.object_names.append(name)
            elif key == "mtllib":
                for lib in parts[1:]:
                    try:
                        mtl = confined_path(p.parent, lib)
                    except ValueError as exc:
                        raise ValueError(f"{p}:{lineno}: material library {exc}") from None
                    self.library.update(_parse_mtl(mtl))
            elif key == "usemtl":
                name = " ".join(parts[1:])
                if name not in self.mat_index:
                    self.mat_index[name] = len(self.materials)
                    self.materials.append(self.library.get(name, Material(name=name)))
                self.current_mat = self.mat_index[name]

    def _face(self, parts: list[str], line: str, lineno: int) -> None:
        """One 'f' line: fan-triangulated, as Blender's importer does for convex faces."""
        p = self.p
        if len(parts) < 4:
            raise ValueError(f"{p}:{lineno}: face needs at least 3 vertices")
        if self.current_obj < 0:
            self.object_names.append(p.stem)
            self.current_obj = 0
        if self.current_mat < 0:
            self.current_mat = len(self.materials)
            self.mat_index[""] = self.current_mat
            self.materials.append(Material(name="default"))
        nv = len(self.verts)
        if len(parts) == 4 and "/" not in line:  # fast path: a plain triangle "f a b c"
            try:
                a, b, cc = int(parts[1]), int(parts[2]), int(parts[3])
            except ValueError:
                raise ValueError(f"{p}:{lineno}: malformed face index in {line.strip()!r}") from None
            if 0 < a <= nv and 0 < b <= nv and 0 < cc <= nv:
                self.corners_v.extend((a - 1, b - 1, cc - 1))
                self.corners_n.extend((-1, -1, -1))
                self.tri_mat.append(self.current_mat)
                self.tri_obj.append(self.current_obj)
                return
        fv, fn = [], []
        for tok in parts[1:]:
            sub = tok.split("/")
            fv.append(self._resolve(sub[0], nv, lineno, "vertex"))
            fn.append(self._resolve(sub[2], len(self.vnormals), lineno, "normal") if len(sub) > 2 and sub[2]
                      else -1)
        for k in range(1, len(fv) - 1):
            self.corners_v.extend((fv[0], fv[k], fv[k + 1]))
            self.corners_n.extend((fn[0], fn[k], fn[k + 1]))
            self.tri_mat.append(self.current_mat)
            self.tri_obj.append(self.current_obj)

    def _resolve(self, token: str, count: int, lineno: int, kind: str) -> int:
        try:
            i = int(token)
        except ValueError:
            raise ValueError(f"{self.p}:{lineno}: malformed face index {token!r}") from None
        j = i - 1 if i > 0 else count + i
        if i == 0 or not 0 <= j < count:
            raise ValueError(f"{self.p}:{lineno}: {kind} index {i} out of range (have {count})")
        return j

    def scene_data(self, up_axis: str) -> SceneData:
        p = self.p
        if not self.corners_v:
            raise ValueError(f"{p}: the file contains no faces (empty scene)")
        positions = np.asarray(self.verts, dtype=np.float64)
        if not np.all(np.isfinite(positions)):
            raise ValueError(f"{p}: vertex positions contain NaN or Inf")
        cv = np.asarray(self.corners_v, dtype=np.int64)
        cn = np.asarray(self.corners_n, dtype=np.int64)
        normals: np.ndarray | None = None
        if (cn >= 0).any():
            positions, normals, tris = self._split_by_normals(positions, cv, cn)
        else:
            tris = cv.reshape(-1, 3)
        # Drop objects without faces (an 'o' line followed by another 'o') and renumber the rest.
        obj = np.asarray(self.tri_obj, dtype=np.int64)
        used = np.unique(obj)
        remap = np.full(len(self.object_names), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        if up_axis == "Y":
            positions = positions @ _Y_TO_Z.T
            if normals is not None:
                normals = normals @ _Y_TO_Z.T
        return SceneData(
            positions=positions.astype(np.float32),
            triangles=tris.astype(np.uint32),
            normals=None if normals is None else normals.astype(np.float32),
            material_ids=np.asarray(self.tri_mat, dtype=np.uint32),
            object_ids=remap[obj].astype(np.uint32),
            materials=self.materials,
            source=str(p),
            object_names=[self.object_names[i] for i in used],
        )

    def _split_by_normals(self, positions: np.ndarray, cv: np.ndarray, cn: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One output vertex per (position, normal) pair: (positions, unit normals, triangles)."""
        nrm = np.asarray(self.vnormals, dtype=np.float64)
        if not np.all(np.isfinite(nrm)):
            raise ValueError(f"{self.p}: vertex normals contain NaN or Inf")
        pairs = np.stack([cv, cn], axis=1)
        uniq, inverse = np.unique(pairs, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        out_pos = positions[uniq[:, 0]]
        has_n = uniq[:, 1] >= 0
        out_nrm = np.zeros_like(out_pos)
        out_nrm[has_n] = nrm[uniq[has_n, 1]]
        tris = inverse.reshape(-1, 3)
        if not has_n.all():  # corners without a normal: area-weighted normals of their faces
            out_nrm[~has_n] = smooth_normals(out_pos, tris)[~has_n]
        length = np.linalg.norm(out_nrm, axis=1, keepdims=True)
        out_nrm = np.where(length > 0, out_nrm / np.where(length > 0, length, 1.0), 0.0)
        return out_pos, out_nrm, tris
