"""The scene assembler: meshes (once each), instances, materials, textures, lights, world and camera
collected while the depsgraph is read, then built into one ``SceneData`` in world space."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .conversions import DEFAULT_BASE_COLOR, MaterialInputs, material_from_inputs, texture_from_image
from .meshes import Instance, MeshArrays, transform_mesh
from .notes import Notes

if TYPE_CHECKING:
    from sim_core.scene_data import Light, Material, SceneData, Texture


class SceneAssembler:
    """Collects meshes (once each), instances, materials, lights, world and camera; builds SceneData."""

    def __init__(self) -> None:
        self.notes = Notes()
        self.meshes: dict[Any, MeshArrays] = {}
        self.instances: list[Instance] = []
        self.materials: list[Material] = []
        self._material_index: dict[Any, int] = {}
        self.lights: list[Light] = []
        self.textures: list[Texture] = []
        self._texture_index: dict[Any, int] = {}
        self._inputs: dict[Any, MaterialInputs] = {}
        self.environment: np.ndarray | tuple[float, float, float] | None = None
        self.environment_strength = 1.0
        self.environment_rotation = 0.0
        self.cameras: list[Any] = []
        self.pass_indices: list[int] = []  # of the built scene's objects (after build)

    def material_index(self, key: Any, make: Any) -> int:
        """The scene index of the material known by ``key`` (``make()`` builds it the first time)."""
        idx = self._material_index.get(key)
        if idx is None:
            idx = len(self.materials)
            self.materials.append(make())
            self._material_index[key] = idx
        return idx

    def principled_index(self, key: Any, read: Callable[[], MaterialInputs], *, uvs: bool) -> int:
        """The scene index of a node material (inputs from ``read()``, called once per key). A base-colour
        image becomes a shared texture on meshes with UVs; on a mesh without UVs the material's variant
        shows the image's mean colour (noted)."""
        inputs = self._inputs.get(key)
        if inputs is None:
            inputs = self._inputs[key] = read()
        textured = inputs.base_image is not None and uvs

        def make() -> Material:
            subject = f"material {inputs.name!r}"
            texture = None
            if textured:
                try:
                    texture = self.texture_index(inputs)
                except ValueError as exc:
                    self.notes.warn(subject, f"image texture shows its mean colour: {exc}")
            elif inputs.base_image is not None:
                self.notes.warn(subject, f"image texture {inputs.base_image.name!r} on a mesh without a UV "
                                         "map: shows its mean colour")
            return material_from_inputs(inputs, self.notes, texture)

        return self.material_index((key, textured), make)

    def texture_index(self, inputs: MaterialInputs) -> int:
        image = inputs.base_image
        assert image is not None
        key = (image.name, inputs.wrap, inputs.image_alpha)
        idx = self._texture_index.get(key)
        if idx is None:
            texture = texture_from_image(image, inputs.wrap, inputs.image_alpha)
            idx = self._texture_index[key] = len(self.textures)
            self.textures.append(texture)
        return idx

    def default_material(self) -> int:
        from sim_core.scene_data import Material  # lazy: the native core loads on first use

        return self.material_index(("<default>",), lambda: Material(base_color=DEFAULT_BASE_COLOR,
                                                                     roughness=0.5, name="default"))

    def add_mesh(self, key: Any, mesh: MeshArrays) -> None:
        self.meshes[key] = mesh

    def add_instance(self, mesh_key: Any, matrix: Any, slot_materials: Sequence[int], name: str,
                     pass_index: int = 0) -> None:
        if mesh_key not in self.meshes:
            raise KeyError(f"mesh {mesh_key!r} was not added")
        self.instances.append(Instance(mesh_key, np.asarray(matrix, dtype=np.float64).reshape(4, 4),
                                       tuple(int(i) for i in slot_materials), name, int(pass_index)))

    def add_light(self, light: Light | None) -> None:
        if light is not None:
            self.lights.append(light)

    def build(self, source: str = "", transforms: dict[Any, Any] | None = None) -> SceneData:
        """World-space arrays of every instance (one object id each, in instance order).

        ``transforms`` (an incremental translation's table, by mesh key and matrix): instances found there
        are not transformed again; afterwards it holds exactly this scene's instances. Mesh keys must then
        name a mesh's content (a re-read mesh gets a new key)."""
        from sim_core.scene_data import SceneData  # lazy: the native core loads on first use

        parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, MeshArrays, np.ndarray]] = []
        names: list[str] = []
        pass_indices: list[int] = []
        used: dict[Any, Any] = {}
        for inst in self.instances:
            mesh = self.meshes[inst.mesh_key]
            if mesh.triangle_count == 0:
                continue
            key = (inst.mesh_key, inst.matrix.tobytes())
            try:
                p, n, t = used[key] = (transforms.get(key) if transforms is not None else None) \
                    or used.get(key) or transform_mesh(mesh, inst.matrix)
            except ValueError as exc:
                self.notes.warn(f"object {inst.name!r}", f"{exc}; left out")
                continue
            table = np.asarray(inst.slot_materials or (self.default_material(),), dtype=np.uint32)
            parts.append((p, n, t, mesh, table))
            names.append(inst.name)
            pass_indices.append(inst.pass_index)
        if transforms is not None:
            transforms.clear()
            transforms.update(used)
        if not names:
            raise ValueError("nothing to render: the scene has no visible geometry for rendering")
        self.pass_indices = pass_indices
        if len(self.lights) > 32:
            kept = sorted(self.lights, key=lambda lt: -lt.intensity)[:32]
            self.notes.warn("lights", f"{len(self.lights)} lights, the simulator takes 32: kept the 32 "
                                      "strongest")
            self.lights = kept
        # one concatenation per array, offsets and material tables applied per triangle at once
        tri_counts = np.array([t.shape[0] for _, _, t, _, _ in parts], dtype=np.int64)
        vertex_counts = np.array([p.shape[0] for p, _, _, _, _ in parts], dtype=np.int64)
        vertex_offsets = np.concatenate(([0], np.cumsum(vertex_counts)[:-1]))
        triangles = np.concatenate([t for _, _, t, _, _ in parts]).astype(np.uint32, copy=False)
        triangles = triangles + np.repeat(vertex_offsets, tri_counts).astype(np.uint32)[:, None]
        table_sizes = np.array([len(table) for *_, table in parts], dtype=np.int64)
        table_starts = np.concatenate(([0], np.cumsum(table_sizes)[:-1]))
        slots = np.concatenate([mesh.slots for _, _, _, mesh, _ in parts]).astype(np.int64)
        slots = (np.clip(slots, 0, np.repeat(table_sizes - 1, tri_counts))
                 + np.repeat(table_starts, tri_counts))
        uvs = None
        if self.textures:
            uvs = np.concatenate([mesh.uvs if mesh.uvs is not None else np.zeros((p.shape[0], 2), np.float32)
                                  for p, _, _, mesh, _ in parts]).astype(np.float32, copy=False)
        return SceneData(
            positions=np.concatenate([p for p, *_ in parts]).astype(np.float32, copy=False),
            triangles=triangles,
            normals=np.concatenate([n for _, n, *_ in parts]).astype(np.float32, copy=False),
            material_ids=np.concatenate([table for *_, table in parts])[slots],
            object_ids=np.repeat(np.arange(len(parts), dtype=np.uint32), tri_counts),
            materials=list(self.materials) or [self._fallback_material()],
            lights=list(self.lights),
            cameras=list(self.cameras),
            environment=self.environment,
            environment_strength=self.environment_strength,
            environment_rotation=self.environment_rotation,
            source=source,
            object_names=names,
            uvs=uvs,
            textures=list(self.textures),
        )

    def _fallback_material(self) -> Material:
        from sim_core.scene_data import Material  # lazy: the native core loads on first use

        return Material(name="default")
