"""The artist's scene as the simulator sees it: Blender's evaluated depsgraph -> ``sim_core`` scene data.

One translator for everything that hands a Blender scene to the simulator: the render engine calls
:func:`translate` with the depsgraph Blender gives it (a render depsgraph for F12 and animations, the
viewport's for Rendered shading), and the add-on's optimisation job sends what :func:`translate_for_render`
returns (a render depsgraph made headless through a private render engine), written as a scene file.

This module only reads Blender data into plain values (objects, meshes, lights, camera here; material and
world node trees in ``node_trees.py``); the conversions (units, clamps, mesh assembly, approximations and
their notes) live in ``core/scene_translation``, which has no bpy.
Visibility follows the depsgraph: a render depsgraph holds what Blender renders (``hide_render``, excluded
collections and disabled modifiers already resolved; collection instances of excluded collections
included), with modifiers at render level.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import bpy
import numpy as np

from .camera_path import camera_vfov, render_resolution
from .core.scene_translation import (
    LightInputs,
    Notes,
    SceneAssembler,
    Translation,
    corner_mesh,
    environment_from_inputs,
    light_from_inputs,
)
from .core.scene_translation.cache import Cached, TranslationCache, Update, needs_translation
from .node_trees import NodeTreeReader

__all__ = ["Translation", "TranslationCache", "depsgraph_updates", "translate", "translate_for_render",
           "translate_update"]

#: Object types Cycles reads geometry from through the object itself; curves and text reach the depsgraph
#: as separate mesh instances (their evaluated geometry), so they are not read twice.
_TO_MESH_TYPES = {"SURFACE", "META"}


def translate(depsgraph: bpy.types.Depsgraph, *, camera: bool = True,
              cache: TranslationCache | None = None) -> Translation:
    """Translate an evaluated depsgraph (render or viewport) into scene data plus notes.

    Reads every object instance the depsgraph shows (meshes once per evaluated mesh, then each instance's
    matrix), materials through their active Cycles output, lights, the world and, with ``camera``, the
    scene camera at the depsgraph's frame. Must run on Blender's main thread (or inside a render engine's
    ``render``/``view_update``, where the depsgraph is valid). Raises ValueError if nothing is visible.

    ``cache`` (the viewport's, told of each update's changes by ``TranslationCache.invalidate``): reuse
    the meshes, materials, world and instance transforms an edit did not change; the result equals a
    fresh translation's.
    """
    start = time.perf_counter()
    reader = _Reader(depsgraph, cache)
    reader.read_instances()
    reader.read_world()
    if camera:
        reader.read_camera()
    data = reader.assembler.build(source="", transforms=None if cache is None else cache.transforms)
    if cache is not None:
        cache.keep_only(reader.assembler.meshes, reader.material_keys)
    stats = {
        "mode": str(depsgraph.mode),
        "frame": int(depsgraph.scene_eval.frame_current),
        "instances": len(data.object_names),
        "unique_meshes": len(reader.assembler.meshes),
        "mesh_reads": reader.mesh_reads,
        "mesh_reuses": reader.mesh_reuses,
        "triangles": int(data.triangles.shape[0]),
        "materials": len(data.materials),
        "lights": len(data.lights),
        "environment": ("map" if isinstance(data.environment, np.ndarray)
                        else "constant" if data.environment is not None else "default"),
        "seconds": round(time.perf_counter() - start, 4),
    }
    return Translation(scene_data=data, notes=reader.assembler.notes.as_list(), stats=stats,
                       pass_indices=list(reader.assembler.pass_indices))


def depsgraph_updates(depsgraph: bpy.types.Depsgraph) -> list[Update]:
    """The depsgraph's updates (what changed since the last evaluation) as plain values."""
    out = []
    for u in depsgraph.updates:
        idb = u.id
        out.append(Update(idb.id_type, getattr(idb, "type", "") if idb.id_type == "OBJECT" else "",
                          u.is_updated_geometry, u.is_updated_transform, u.is_updated_shading,
                          idb.original.name_full))
    return out


def translate_update(depsgraph: bpy.types.Depsgraph, cache: TranslationCache, *, force: bool = False
                     ) -> Translation | None:
    """The viewport's translation after a depsgraph update: None when the update changes nothing the
    simulator sees (a camera moving, a selection), else the scene translated incrementally through
    ``cache`` (``force``: translate even then, e.g. when the viewport has no scene yet)."""
    changes = depsgraph_updates(depsgraph)
    cache.invalidate(changes)
    if not (force or needs_translation(changes)):
        return None
    return translate(depsgraph, camera=False, cache=cache)


def translate_for_render(scene: bpy.types.Scene | None = None,
                         view_layer: bpy.types.ViewLayer | None = None) -> Translation:
    """The scene as a final render sees it: modifiers at render level, render visibility, the current frame.

    Blender makes render depsgraphs only for render engines, so this renders the view layer with a private
    engine whose ``render`` runs :func:`translate` and draws nothing; the scene's own engine and output
    settings are restored afterwards. Needs the scene camera (as any render does). Main thread only.
    """
    scene = scene or bpy.context.scene
    layer = view_layer or (bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0])
    if scene.camera is None:
        raise ValueError("the scene has no active camera: a render needs one")
    outcome: dict[str, Any] = {}

    class RENDER_BUDGET_translate_engine(bpy.types.RenderEngine):
        bl_idname = "RENDER_BUDGET_TRANSLATE"
        bl_label = "Render Budget scene translation"
        bl_use_postprocess = False
        bl_use_preview = False

        def render(self, depsgraph: bpy.types.Depsgraph) -> None:
            if depsgraph.view_layer_eval.name != layer.name or "translation" in outcome:
                return
            try:
                outcome["translation"] = translate(depsgraph)
            except BaseException as exc:  # Blender swallows errors raised here: carry it out
                outcome["error"] = exc

    from .core.progressive import workers_paused  # lazy: it loads the native core

    saved = (scene.render.engine, scene.render.use_compositing, scene.render.use_sequencer)
    # No other Python thread may run while a render engine type is registered and Blender renders with
    # it (a viewport worker running then coincided with a crash inside Blender): hold them still.
    with workers_paused():
        bpy.utils.register_class(RENDER_BUDGET_translate_engine)
        try:
            scene.render.engine = RENDER_BUDGET_translate_engine.bl_idname
            scene.render.use_compositing = False
            scene.render.use_sequencer = False
            with bpy.context.temp_override(scene=scene, view_layer=layer):
                result = bpy.ops.render.render(layer=layer.name, scene=scene.name)
        finally:
            scene.render.engine, scene.render.use_compositing, scene.render.use_sequencer = saved
            bpy.utils.unregister_class(RENDER_BUDGET_translate_engine)
    if "error" in outcome:
        raise outcome["error"]
    if "FINISHED" not in result:
        raise RuntimeError("Blender did not start a render to translate the scene (is a render already "
                           "running?); try again when it has finished")
    if "translation" not in outcome:
        raise RuntimeError(f"Blender rendered no view layer named {layer.name!r}: is it enabled for "
                           "rendering?")
    return outcome["translation"]


# -- reading -------------------------------------------------------------------------------------------
class _Reader:
    def __init__(self, depsgraph: bpy.types.Depsgraph, cache: TranslationCache | None = None) -> None:
        self.depsgraph = depsgraph
        self.scene = depsgraph.scene_eval
        self.view_layer = depsgraph.view_layer_eval
        self.assembler = SceneAssembler()
        self.notes: Notes = self.assembler.notes
        self.node_trees = NodeTreeReader(self.notes)
        self.cache = cache
        if cache is not None:
            self.node_trees.images = cache.images  # image pixels survive edits that leave images alone
        self.mesh_reads = 0
        self.mesh_reuses = 0
        self.material_keys: set[Any] = set()
        self._temporary = 0
        self._names: dict[str, int] = {}

    def _recorded(self, read: Callable[[], Any]) -> Cached[Any]:
        """``read()``'s value with the notes it made (also added to this translation's notes)."""
        outer, inner = self.notes, Notes()
        self.notes = self.node_trees.notes = inner
        try:
            value = read()
        finally:
            self.notes = self.node_trees.notes = outer
        cached = Cached(value, tuple(inner))
        cached.replay(outer)
        return cached

    # objects ------------------------------------------------------------------------------------------
    def read_instances(self) -> None:
        viewport = self.depsgraph.mode == "VIEWPORT"
        for inst in self.depsgraph.object_instances:
            obj = inst.object
            if obj.type == "LIGHT":
                if inst.show_self:
                    self.read_light(obj, np.array(inst.matrix_world, dtype=np.float64))
                continue
            if not inst.show_self:
                continue
            if obj.type != "MESH" and obj.type not in _TO_MESH_TYPES:
                continue
            original = obj.original
            if viewport and not inst.is_instance and not original.visible_get(
                    view_layer=self.depsgraph.view_layer):
                continue
            if not obj.visible_camera:
                self.notes.info(f"object {original.name!r}", "invisible to camera rays in Cycles: left out "
                                                             "(its shadows and reflections too)")
                continue
            if self._holdout(obj):
                self.notes.info(f"object {original.name!r}", "holdout is not simulated: rendered as a normal "
                                                             "surface")
            key = self.read_mesh(obj)
            if key is None:
                continue
            name = self._instance_name(inst)
            has_uvs = self.assembler.meshes[key].uvs is not None
            self.assembler.add_instance(key, np.array(inst.matrix_world, dtype=np.float64),
                                        self.slot_materials(obj, has_uvs), name, obj.pass_index)

    def _holdout(self, obj: bpy.types.Object) -> bool:
        try:
            return bool(obj.is_holdout or obj.original.holdout_get(view_layer=self.depsgraph.view_layer))
        except (AttributeError, TypeError, RuntimeError):
            return bool(getattr(obj, "is_holdout", False))

    def _instance_name(self, inst: bpy.types.DepsgraphObjectInstance) -> str:
        """The object's name (a curve's or text's mesh too); an instance's is "<object> in <instancer>" (a
        geometry-nodes instance, which Blender names after its instancer, goes by its mesh's name)."""
        obj, parent = inst.object, inst.parent
        own_geometry = parent is not None and obj.original == parent.original and obj.data is not None
        if not inst.is_instance or parent is None:
            base = obj.name
        elif own_geometry and parent.type != "MESH":  # a curve or text object's evaluated mesh
            base = parent.name
        else:
            base = f"{obj.data.name if own_geometry else obj.name} in {parent.name}"
        n = self._names.get(base, 0)
        self._names[base] = n + 1
        return base if n == 0 else f"{base} #{n + 1}"

    def read_mesh(self, obj: bpy.types.Object) -> Any:
        """Key of the object's evaluated mesh in the assembler, reading it the first time it is seen (in
        this translation, or with a cache, since the depsgraph last evaluated it)."""
        if obj.type == "MESH":
            mesh = obj.data
            # the session id changes whenever the depsgraph evaluates the mesh again: with the address and
            # the element counts, a key of the mesh's content
            key = ("mesh", mesh.as_pointer(), mesh.session_uid, len(mesh.vertices), len(mesh.loops),
                   len(mesh.loop_triangles))
            if key not in self.assembler.meshes:
                self.assembler.add_mesh(key, self._cached_mesh(key, mesh, obj))
            return key
        mesh = obj.to_mesh()  # metaballs and NURBS surfaces: a temporary mesh, read now and freed
        try:
            if mesh is None:
                return None
            self._temporary += 1
            # unique among the cache's translations too (its transforms are keyed by mesh)
            key = ("temporary", self._temporary, 0 if self.cache is None else self.cache.extractions)
            self.assembler.add_mesh(key, self._extract(mesh, obj).value)
            return key
        finally:
            obj.to_mesh_clear()

    def _cached_mesh(self, key: Any, mesh: bpy.types.Mesh, obj: bpy.types.Object) -> Any:
        cache = self.cache
        if cache is not None and obj.original.name_full not in cache.dirty_objects:
            cached = cache.meshes.get(key)
            if cached is not None:
                self.mesh_reuses += 1
                cache.reuses += 1
                return cached.replay(self.notes)
        cached = self._extract(mesh, obj)
        if cache is not None:
            cache.meshes[key] = cached
        return cached.value

    def _extract(self, mesh: bpy.types.Mesh, obj: bpy.types.Object) -> Cached[Any]:
        if self.cache is not None:
            self.cache.extractions += 1
        return self._recorded(partial(self._mesh_arrays, mesh, obj))

    def _mesh_arrays(self, mesh: bpy.types.Mesh, obj: bpy.types.Object) -> Any:
        self.mesh_reads += 1
        n_vert, n_corner, n_tri = len(mesh.vertices), len(mesh.loops), len(mesh.loop_triangles)
        co = np.empty(n_vert * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        corner_vertices = np.empty(n_corner, np.int32)
        mesh.loops.foreach_get("vertex_index", corner_vertices)
        normals = np.empty(n_corner * 3, np.float32)
        mesh.corner_normals.foreach_get("vector", normals)
        tri_corners = np.empty(n_tri * 3, np.int32)
        mesh.loop_triangles.foreach_get("loops", tri_corners)
        tri_slots = np.empty(n_tri, np.int32)
        mesh.loop_triangles.foreach_get("material_index", tri_slots)
        uvs = None
        layer = next((uv for uv in mesh.uv_layers if uv.active_render), None)
        if layer is not None and n_corner:
            uvs = np.empty(n_corner * 2, np.float32)
            layer.uv.foreach_get("vector", uvs)
        if not (np.all(np.isfinite(co)) and np.all(np.isfinite(normals))):
            self.notes.warn(f"object {obj.original.name!r}", "its mesh holds NaN or infinite coordinates: "
                                                             "left out")
            return corner_mesh(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
        return corner_mesh(co.reshape(-1, 3), corner_vertices, normals.reshape(-1, 3),
                           tri_corners.reshape(-1, 3), tri_slots, None if uvs is None else uvs.reshape(-1, 2))

    # materials ----------------------------------------------------------------------------------------
    def slot_materials(self, obj: bpy.types.Object, has_uvs: bool) -> list[int]:
        """Scene material index of each of the object's material slots (Blender's default for empty ones);
        ``has_uvs``: whether the object's mesh has a UV map its textures can use."""
        slots = [s.material for s in obj.material_slots]
        if not slots and obj.type == "MESH":
            slots = list(obj.data.materials)
        out = []
        for mat in slots:
            if mat is None:
                out.append(self.assembler.default_material())
                continue
            key = ("material", mat.original.name_full)
            self.material_keys.add(key)
            out.append(self.assembler.principled_index(key, partial(self._material_inputs, key, mat),
                                                       uvs=has_uvs))
        return out

    def _material_inputs(self, key: Any, mat: bpy.types.Material) -> Any:
        cache = self.cache
        cached = None if cache is None else cache.materials.get(key)
        if cached is not None:
            return cached.replay(self.notes)
        cached = self._recorded(partial(self.node_trees.material_inputs, mat))
        if cache is not None:
            cache.materials[key] = cached
        return cached.value

    # lights -------------------------------------------------------------------------------------------
    def read_light(self, obj: bpy.types.Object, matrix: np.ndarray) -> None:
        light = obj.data
        subject = f"light {obj.name!r}"
        color = np.asarray(light.color[:3], dtype=np.float64)
        if getattr(light, "use_temperature", False):
            color = color * np.asarray(light.temperature_color[:3], dtype=np.float64)
        if getattr(light, "use_nodes", False) and light.node_tree is not None:
            self.notes.info(subject, "light node tree ignored: its colour and power are used")
        if not light.use_shadow:
            self.notes.info(subject, "'cast shadow' off is not simulated: it casts shadows")
        self.assembler.add_light(light_from_inputs(LightInputs(
            name=obj.name, kind=light.type, matrix_world=matrix, energy=float(light.energy),
            color=tuple(color), shadow_soft_size=float(getattr(light, "shadow_soft_size", 0.0)),
            spot_size=float(getattr(light, "spot_size", math.pi / 4)),
            spot_blend=float(getattr(light, "spot_blend", 0.15)), angle=float(getattr(light, "angle", 0.0)),
            shape=str(getattr(light, "shape", "SQUARE")), size=float(getattr(light, "size", 0.0)),
            size_y=float(getattr(light, "size_y", 0.0)), exposure=float(getattr(light, "exposure", 0.0)),
            normalize=bool(getattr(light, "normalize", True)),
        ), self.notes))

    # world --------------------------------------------------------------------------------------------
    def read_world(self) -> None:
        world = self.scene.world
        if world is None:
            self.assembler.environment = (0.0, 0.0, 0.0)  # Cycles renders a scene without a world black
            return
        key = world.original.name_full
        cache = self.cache
        if cache is not None and cache.world is not None and cache.world[0] == key:
            cached = cache.world[1]
            cached.replay(self.notes)
        else:
            cached = self._recorded(lambda: environment_from_inputs(self.node_trees.world_inputs(world),
                                                                    self.notes))
            if cache is not None:
                cache.world = (key, cached)
        env, strength, rotation = cached.value
        self.assembler.environment = env
        self.assembler.environment_strength = strength
        self.assembler.environment_rotation = rotation

    # camera -------------------------------------------------------------------------------------------
    def read_camera(self) -> None:
        from sim_core.scene_data import CameraData  # lazy: the native core loads on first use

        cam = self.scene.camera
        if cam is None:
            return
        if cam.type != "CAMERA" or cam.data.type != "PERSP":
            self.notes.warn("camera", f"{cam.name!r} is not a perspective camera: not carried")
            return
        width, height = render_resolution(self.scene)
        cam_eval = cam.evaluated_get(self.depsgraph) if not cam.is_evaluated else cam
        self.assembler.cameras.append(CameraData(
            matrix_world=np.array(cam_eval.matrix_world, dtype=np.float64),
            vfov=camera_vfov(cam_eval, self.scene), aspect=width / height, name=cam.name))


