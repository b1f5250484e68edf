"""glTF 2.0 loader (.glb and .gltf) for scenes exported by Blender, decoded with numpy.

What it reads: triangle meshes (indexed or not, strips and fans too) placed by the node hierarchy,
metallic-roughness materials with KHR_materials_transmission / _ior / _emissive_strength, alpha modes
(MASK -> clip, BLEND -> hashed), base-colour textures with their texture coordinates (TEXCOORD_n,
KHR_texture_transform baked into the UVs, sampler wrap modes; one decoded image per texture and sampler,
shared by every material using it), KHR_lights_punctual lights and perspective cameras. Other textures
(normal, metallic-roughness, emission maps), skins, morph targets and animation are ignored. glTF's UVs
have v pointing down from the image's top; the loader flips them to Blender's convention (v up).

Frames: glTF is Y-up, the project's world is Blender's Z-up. The conversion happens here, once, in
:data:`GLTF_TO_BLENDER` (``(x, y, z)_gltf -> (x, -z, y)``), applied to every node's world matrix.

Light units: Blender's exporter (lighting mode 'SPEC', its default) writes point and spot lights as
``W / (4 pi) * 683`` candela and sun lights as ``W/m^2 * 683`` lux. The loader turns them back into
Blender's watts and W/m^2 (``/ 683``, :data:`LUMENS_PER_WATT`, times 4 pi for point and spot) and builds
the light with ``Light.from_blender``, the one conversion to the simulator's units (checked against
Cycles): a 1000 W Blender point light loads as 1000 / (4 pi) = 79.6 W/sr. A spot's cone is glTF's outer
cone (Blender's spot_size / 2) and its blend comes back from the inner cone, which the exporter writes as
outer * (1 - spot_blend). Area lights cannot travel in glTF (the exporter drops them with a warning); a
scene translated from Blender's depsgraph carries them.

Two scene facts glTF cannot carry travel as extras (custom properties Blender exports with
``export_extras=True``): the environment (:data:`ENVIRONMENT_EXTRAS_KEY` on the scene: an EXR file name
next to the .glb, or an RGB colour) and light radii (:data:`LIGHT_RADIUS_EXTRAS_KEY`).

Files outside the document (buffer and image URIs, the environment EXR) follow one policy,
:func:`.document.referenced_file`, checked for every reference before any of them is read: with
``self_contained=True`` (scenes uploaded to the service) only the GLB binary chunk and ``data:`` URIs
are allowed; otherwise relative files are read, but only inside the scene file's own folder (resolved
paths, so neither ``..`` nor a symbolic link leads out). Error messages name the reference as the file
wrote it, never a resolved path or the bytes of another file.

The package, by concept: :mod:`.document` (the container and that file policy), :mod:`.accessors` (buffer
views, accessors, index lists), :mod:`.materials` (materials and base-colour textures), :mod:`.nodes` (the
node walk, lights, cameras, GPU instances); this module walks the nodes and assembles the scene data.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ...geometry import smooth_normals
from ...image import load_exr
from ...scene_data import CameraData, Light, Material, SceneData
from ..confined import shown
from .accessors import primitive_triangles, read_accessor
from .document import ENVIRONMENT_EXTRAS_KEY, Document, environment_extra, read_document, referenced_file
from .materials import MAX_LOADED_TEXTURE_SIDE, BaseColorTexture, TextureTable, primitive_uvs, read_material
from .nodes import (
    GLTF_TO_BLENDER,
    LIGHT_RADIUS_EXTRAS_KEY,
    LUMENS_PER_WATT,
    gpu_instances,
    read_camera,
    read_light,
    walk_nodes,
)

__all__ = ["ENVIRONMENT_EXTRAS_KEY", "GLTF_TO_BLENDER", "LIGHT_RADIUS_EXTRAS_KEY", "LUMENS_PER_WATT",
           "MAX_LOADED_TEXTURE_SIDE", "load_gltf"]


def load_gltf(path: str | os.PathLike[str], *, self_contained: bool = False) -> SceneData:
    """Load a .glb/.gltf into flat arrays in Blender's world frame (Z up, metres).

    ``self_contained=True`` (files from untrusted clients) refuses every reference outside the file
    itself: only the GLB binary chunk and ``data:`` URIs; otherwise relative files inside the scene's
    own folder are read too (a .gltf next to its .bin, textures and environment map).

    One object id per mesh instance (node with a mesh, or each of its EXT_mesh_gpu_instancing instances),
    in depth-first node order; degenerate triangles are kept (the core drops and counts them). Raises
    FileNotFoundError for missing files and ValueError for anything malformed: not glTF, truncated
    buffers, NaN/Inf positions, out-of-range indices, fields of the wrong type, or a scene without a
    single triangle. Files come from users (uploads), so no other exception type escapes.
    """
    p = Path(path)
    try:
        return _load(p, self_contained)
    except (KeyError, TypeError, AttributeError, IndexError, OverflowError) as exc:
        raise ValueError(f"{p}: malformed glTF ({type(exc).__name__}: {exc})") from exc
    except (MemoryError, RecursionError) as exc:
        raise ValueError(f"{p}: glTF too large or too deeply nested to load ({type(exc).__name__})") from exc


def _load(p: Path, self_contained: bool) -> SceneData:
    doc = read_document(p, self_contained=self_contained)
    table = TextureTable(doc)
    parts = _Parts(doc, [read_material(doc, i, table) for i in range(len(doc.gltf.get("materials", [])))])
    for node_index, world_g in walk_nodes(doc):
        parts.add_node(node_index, GLTF_TO_BLENDER @ world_g)
    arrays = parts.arrays()
    return SceneData(
        **arrays,
        materials=parts.materials,
        lights=parts.lights,
        cameras=parts.cameras,
        environment=_environment(doc),
        source=str(p),
        object_names=parts.object_names,
        textures=table.textures,
    )


class _Parts:
    """The scene in Blender's world frame as per-primitive parts (positions, normals, UVs, triangles,
    material and object ids), filled by one walk over the node hierarchy and concatenated at the end."""

    def __init__(self, doc: Document,
                 decoded_materials: list[tuple[Material, BaseColorTexture | None]]) -> None:
        self.doc = doc
        self.materials = [m for m, _ in decoded_materials]
        self.samplings = [t for _, t in decoded_materials]
        self.default_material: int | None = None
        self.positions: list[np.ndarray] = []
        self.normals: list[np.ndarray | None] = []
        self.uvs: list[np.ndarray | None] = []
        self.triangles: list[np.ndarray] = []
        self.material_ids: list[np.ndarray] = []
        self.object_ids: list[np.ndarray] = []
        self.object_names: list[str] = []
        self.lights: list[Light] = []
        self.cameras: list[CameraData] = []
        self.vertex_count = 0
        self._decoded: dict[int, tuple[np.ndarray, np.ndarray | None]] = {}  # by id() of the primitive

    def add_node(self, node_index: int, world_b: np.ndarray) -> None:
        """A node's light, camera and mesh instances (one object each)."""
        doc = self.doc
        node = doc.gltf.get("nodes", [])[node_index]
        name = str(node.get("name", f"node_{node_index}"))
        ext = node.get("extensions", {})
        if "KHR_lights_punctual" in ext:
            self.lights.append(read_light(doc, int(ext["KHR_lights_punctual"]["light"]), world_b, name))
        if "camera" in node:
            camera = read_camera(doc, int(node["camera"]), world_b, name)
            if camera is not None:
                self.cameras.append(camera)
        if "mesh" not in node:
            return
        meshes = doc.gltf.get("meshes", [])
        mi = int(node["mesh"])
        if not 0 <= mi < len(meshes):
            raise ValueError(f"{doc.path}: mesh {mi} does not exist")
        instancing = ext.get("EXT_mesh_gpu_instancing")
        placements = [(name, world_b)]
        if instancing is not None:  # one object per GPU instance: node world @ instance TRS
            placements = [(f"{name}.{k}", world_b @ m)
                          for k, m in enumerate(gpu_instances(doc, instancing, f"node {name!r}"))]
        for name_k, world_k in placements:
            self._add_instance(mi, name_k, world_k)

    def _add_instance(self, mi: int, name: str, world: np.ndarray) -> None:
        mesh = self.doc.gltf.get("meshes", [])[mi]
        object_id = len(self.object_names)
        self.object_names.append(name)
        m3 = world[:3, :3]
        # Inverse transpose up to a positive scale (normals are renormalised): the cofactor matrix
        # times the determinant's sign; closed form (np.linalg.inv is slow on many small matrices).
        c0, c1, c2 = m3[:, 0], m3[:, 1], m3[:, 2]
        cof = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)
        det = float(np.dot(c0, cof[:, 0]))
        # A zero scale (hidden object) makes every triangle degenerate: kept; the core drops them.
        normal_matrix = cof * math.copysign(1.0, det)
        for pi, prim in enumerate(mesh.get("primitives", [])):
            what = f"{self.doc.path}: mesh {mi} ({mesh.get('name', '')!r}) primitive {pi}"
            self._add_primitive(prim, what, world, normal_matrix, det < 0.0, object_id)

    def _add_primitive(self, prim: dict[str, Any], what: str, world: np.ndarray, normal_matrix: np.ndarray,
                       mirrored: bool, object_id: int) -> None:
        attrs = prim.get("attributes", {})
        if "POSITION" not in attrs:
            raise ValueError(f"{what}: no POSITION attribute")
        pos, nrm = self._vertices(prim, attrs, what)
        tris = primitive_triangles(self.doc, prim, pos.shape[0], what)
        if tris is None or tris.shape[0] == 0:
            return
        world_pos = pos @ world[:3, :3].T + world[:3, 3]
        if not np.all(np.isfinite(world_pos)):
            raise ValueError(f"{what}: transformed positions overflow to Inf")
        if mirrored:
            tris = tris[:, [0, 2, 1]]
        if nrm is not None:
            wn = nrm @ normal_matrix.T
            length = np.linalg.norm(wn, axis=1, keepdims=True)
            wn = np.where(length > 0, wn / np.where(length > 0, length, 1.0), 0.0)
        else:
            wn = None
        mat = self._material_index(prim, what)
        sampling = self.samplings[mat] if mat < len(self.samplings) else None
        self.positions.append(world_pos)
        self.normals.append(wn)
        self.uvs.append(None if sampling is None
                        else primitive_uvs(self.doc, attrs, sampling, world_pos.shape[0], what))
        self.triangles.append(tris + self.vertex_count)
        self.material_ids.append(np.full(tris.shape[0], mat, dtype=np.uint32))
        self.object_ids.append(np.full(tris.shape[0], object_id, dtype=np.uint32))
        self.vertex_count += world_pos.shape[0]

    def _vertices(self, prim: dict[str, Any], attrs: dict[str, Any], what: str
                  ) -> tuple[np.ndarray, np.ndarray | None]:
        """A primitive's local positions and normals (float64), decoded once however often it is placed."""
        key = id(prim)
        if key not in self._decoded:
            pos = read_accessor(self.doc, int(attrs["POSITION"]))
            if pos.shape[1] != 3:
                raise ValueError(f"{what}: POSITION must be VEC3")
            pos = pos.astype(np.float64)
            if not np.all(np.isfinite(pos)):
                raise ValueError(f"{what}: POSITION contains NaN or Inf")
            nrm = None
            if "NORMAL" in attrs:
                nrm = read_accessor(self.doc, int(attrs["NORMAL"])).astype(np.float64)
                if nrm.shape != pos.shape:
                    raise ValueError(f"{what}: NORMAL count/shape differs from POSITION")
                if not np.all(np.isfinite(nrm)):
                    raise ValueError(f"{what}: NORMAL contains NaN or Inf")
            self._decoded[key] = (pos, nrm)
        return self._decoded[key]

    def _material_index(self, prim: dict[str, Any], what: str) -> int:
        """The primitive's material, or a shared default one (added the first time it is needed)."""
        if "material" in prim:
            mat = int(prim["material"])
            if not 0 <= mat < len(self.materials):
                raise ValueError(f"{what}: material {mat} does not exist")
            return mat
        if self.default_material is None:
            self.default_material = len(self.materials)
            self.materials.append(Material(name="default"))
        return self.default_material

    def arrays(self) -> dict[str, np.ndarray | None]:
        """The concatenated arrays (SceneData's positions, triangles, normals, material_ids, object_ids and
        uvs). Normals only when some primitive has them (the others get smooth normals); UVs only when
        some textured material is drawn."""
        if not self.triangles:
            raise ValueError(f"{self.doc.path}: the scene contains no triangles (empty scene)")
        positions = np.concatenate(self.positions)
        triangles = np.concatenate(self.triangles)
        normals: np.ndarray | None = None
        if any(n is not None for n in self.normals):
            filled = []
            starts = np.cumsum([0] + [part.shape[0] for part in self.positions[:-1]])
            parts = zip(self.positions, self.normals, self.triangles, starts, strict=True)
            for pos, nrm, tri, start in parts:
                filled.append(nrm if nrm is not None else smooth_normals(pos, tri - start))
            normals = np.concatenate(filled).astype(np.float32)
        uvs: np.ndarray | None = None
        if any(u is not None for u in self.uvs):
            uvs = np.concatenate([u if u is not None else np.zeros((pos.shape[0], 2))
                                  for u, pos in zip(self.uvs, self.positions, strict=True)])
            uvs = uvs.astype(np.float32)
        if positions.shape[0] > np.iinfo(np.uint32).max:
            raise ValueError(f"{self.doc.path}: too many vertices for 32-bit indices")
        return {"positions": positions.astype(np.float32), "triangles": triangles.astype(np.uint32),
                "normals": normals, "material_ids": np.concatenate(self.material_ids),
                "object_ids": np.concatenate(self.object_ids), "uvs": uvs}


def _environment(doc: Document) -> np.ndarray | tuple[float, float, float] | None:
    value = environment_extra(doc.gltf)
    if value is None:
        return None
    if isinstance(value, str):
        exr = referenced_file(doc, value, "environment map")
        if exr is None:
            raise ValueError(f"{doc.path}: the environment map must be an EXR file next to the scene, "
                             "not a data: URI")
        if not exr.is_file():
            raise FileNotFoundError(f"{doc.path}: environment map {shown(value)} not found next to the "
                                    "scene")
        return load_exr(exr)
    rgb = np.asarray(value, dtype=np.float64).reshape(-1)
    if rgb.shape != (3,) or not np.all(np.isfinite(rgb)):
        raise ValueError(f"{doc.path}: environment colour must be 3 finite numbers, got {value!r}")
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))

