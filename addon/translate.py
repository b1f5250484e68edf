"""The artist's scene as the simulator sees it: Blender's evaluated depsgraph -> ``sim_core`` scene data.

One translator for everything that hands a Blender scene to the simulator: the render engine calls
:func:`translate` with the depsgraph Blender gives it (a render depsgraph for F12 and animations, the
viewport's for Rendered shading), and the add-on's optimisation job sends what :func:`translate_for_render`
returns (a render depsgraph made headless through a private render engine), written as a scene file.

This module only reads Blender data into plain values; the conversions (units, clamps, mesh assembly,
approximations and their notes) live in ``core/scene_translation.py``, which has no bpy.
Visibility follows the depsgraph: a render depsgraph holds what Blender renders (``hide_render``, excluded
collections and disabled modifiers already resolved; collection instances of excluded collections
included), with modifiers at render level.
"""

from __future__ import annotations

import math
import time
from typing import Any

import bpy
import numpy as np

from .camera_path import camera_vfov, render_resolution
from .core.scene_translation import (
    ImageData,
    LightInputs,
    MaterialInputs,
    Notes,
    SceneAssembler,
    Translation,
    WorldInputs,
    corner_mesh,
    environment_from_inputs,
    light_from_inputs,
)

__all__ = ["Translation", "translate", "translate_for_render"]

#: Object types Cycles reads geometry from through the object itself; curves and text reach the depsgraph
#: as separate mesh instances (their evaluated geometry), so they are not read twice.
_TO_MESH_TYPES = {"SURFACE", "META"}
_OUTPUT_TARGETS = ("ALL", "CYCLES")
_WRAPS = {"REPEAT": "repeat", "EXTEND": "clamp", "CLIP": "clamp", "MIRROR": "mirror"}


def translate(depsgraph: bpy.types.Depsgraph, *, camera: bool = True) -> Translation:
    """Translate an evaluated depsgraph (render or viewport) into scene data plus notes.

    Reads every object instance the depsgraph shows (meshes once per evaluated mesh, then each instance's
    matrix), materials through their active Cycles output, lights, the world and, with ``camera``, the
    scene camera at the depsgraph's frame. Must run on Blender's main thread (or inside a render engine's
    ``render``/``view_update``, where the depsgraph is valid). Raises ValueError if nothing is visible.
    """
    start = time.perf_counter()
    reader = _Reader(depsgraph)
    reader.read_instances()
    reader.read_world()
    if camera:
        reader.read_camera()
    data = reader.assembler.build(source="")
    stats = {
        "mode": str(depsgraph.mode),
        "frame": int(depsgraph.scene_eval.frame_current),
        "instances": len(data.object_names),
        "unique_meshes": len(reader.assembler.meshes),
        "mesh_reads": reader.mesh_reads,
        "triangles": int(data.triangles.shape[0]),
        "materials": len(data.materials),
        "lights": len(data.lights),
        "environment": ("map" if isinstance(data.environment, np.ndarray)
                        else "constant" if data.environment is not None else "default"),
        "seconds": round(time.perf_counter() - start, 4),
    }
    return Translation(scene_data=data, notes=reader.assembler.notes.as_list(), stats=stats,
                       pass_indices=list(reader.assembler.pass_indices))


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

    saved = (scene.render.engine, scene.render.use_compositing, scene.render.use_sequencer)
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
    def __init__(self, depsgraph: bpy.types.Depsgraph) -> None:
        self.depsgraph = depsgraph
        self.scene = depsgraph.scene_eval
        self.view_layer = depsgraph.view_layer_eval
        self.assembler = SceneAssembler()
        self.notes: Notes = self.assembler.notes
        self.images: dict[str, ImageData | None] = {}
        self.mesh_reads = 0
        self._temporary = 0
        self._names: dict[str, int] = {}

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
        """Key of the object's evaluated mesh in the assembler, reading it the first time it is seen."""
        if obj.type == "MESH":
            mesh = obj.data
            key = ("mesh", mesh.as_pointer())
            if key not in self.assembler.meshes:
                self.assembler.add_mesh(key, self._mesh_arrays(mesh, obj))
            return key
        mesh = obj.to_mesh()  # metaballs and NURBS surfaces: a temporary mesh, read now and freed
        try:
            if mesh is None:
                return None
            self._temporary += 1
            key = ("temporary", self._temporary)
            self.assembler.add_mesh(key, self._mesh_arrays(mesh, obj))
            return key
        finally:
            obj.to_mesh_clear()

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
            out.append(self.assembler.principled_index(("material", mat.original.name_full),
                                                       lambda m=mat: self.material_inputs(m), uvs=has_uvs))
        return out

    def material_inputs(self, mat: bpy.types.Material) -> MaterialInputs:
        subject = f"material {mat.name!r}"
        fallback = MaterialInputs(name=mat.name, base_color=tuple(mat.diffuse_color[:3]),
                                  metallic=float(mat.metallic), roughness=float(mat.roughness))
        tree = mat.node_tree
        if tree is None or not _uses_nodes(mat):
            return fallback
        output = _active_output(tree, "ShaderNodeOutputMaterial")
        if output is None:
            self.notes.warn(subject, "no material output node: its viewport display colour is used")
            return fallback
        surface = output.inputs["Surface"]
        shader = _linked_node(surface)
        if shader is None:
            self.notes.warn(subject, "nothing connected to the material output's Surface: rendered black")
            return MaterialInputs(name=mat.name, base_color=(0.0, 0.0, 0.0))
        if output.inputs.get("Displacement") is not None and output.inputs["Displacement"].is_linked:
            self.notes.info(subject, "displacement is not simulated")
        return self.shader_inputs(mat.name, shader, subject, fallback)

    def shader_inputs(self, name: str, node: bpy.types.Node, subject: str, fallback: MaterialInputs
                      ) -> MaterialInputs:
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfPrincipled":
            return self.principled_inputs(name, node, subject)
        def value(label: str) -> float:
            return self.float_input(node.inputs[label], subject, label)

        color = self.color_input(node.inputs["Color"], subject, "Color") if "Color" in node.inputs else \
            fallback.base_color
        if kind == "ShaderNodeBsdfDiffuse":  # ior 1: no specular layer
            return MaterialInputs(name=name, base_color=color, roughness=1.0, ior=1.0)
        if kind == "ShaderNodeEmission":
            return MaterialInputs(name=name, base_color=(0.0, 0.0, 0.0), emission_color=color,
                                  emission_strength=value("Strength"))
        if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            return MaterialInputs(name=name, base_color=color, metallic=1.0, roughness=value("Roughness"))
        if kind in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"):
            return MaterialInputs(name=name, base_color=color, transmission=1.0, ior=value("IOR"),
                                  roughness=value("Roughness"))
        self.notes.warn(subject, f"shader {node.name!r} ({node.bl_label}) is not a Principled BSDF: "
                                 "approximated by the material's viewport display colour, metallic and "
                                 "roughness")
        return fallback

    def principled_inputs(self, name: str, node: bpy.types.Node, subject: str) -> MaterialInputs:
        inputs = node.inputs
        base_socket = inputs["Base Color"]
        image = None
        base = (1.0, 1.0, 1.0)
        image_node = _image_node(base_socket)
        if image_node is not None:
            image = self.image_texture(image_node, subject)
        if image is None:
            base = self.color_input(base_socket, subject, "Base Color")
        alpha_source = _follow(inputs["Alpha"])
        image_alpha = image is not None and alpha_source is not None and alpha_source[0] == image_node \
            and alpha_source[1].name == "Alpha"
        for label in ("Coat Weight", "Sheen Weight", "Subsurface Weight"):
            sock = inputs.get(label)
            if sock is not None and (sock.is_linked or float(sock.default_value) > 0):
                self.notes.info(subject, f"{label} is not simulated")
        normal = inputs.get("Normal")
        if normal is not None and normal.is_linked:
            self.notes.info(subject, "normal / bump mapping is not simulated")
        return MaterialInputs(
            name=name,
            base_color=base,
            base_image=image,
            metallic=self.float_input(inputs["Metallic"], subject, "Metallic"),
            roughness=self.float_input(inputs["Roughness"], subject, "Roughness"),
            transmission=self.float_input(inputs["Transmission Weight"], subject, "Transmission Weight"),
            ior=self.float_input(inputs["IOR"], subject, "IOR"),
            emission_color=self.color_input(inputs["Emission Color"], subject, "Emission Color"),
            emission_strength=self.float_input(inputs["Emission Strength"], subject, "Emission Strength"),
            alpha=1.0 if image_alpha else self.float_input(inputs["Alpha"], subject, "Alpha"),
            wrap=_WRAPS.get(image_node.extension, "repeat") if image is not None else "repeat",
            image_alpha=image_alpha,
        )

    def image_texture(self, node: bpy.types.Node, subject: str) -> ImageData | None:
        if node.image is None:
            self.notes.warn(subject, f"image texture {node.name!r} has no image: Blender renders it pink; "
                                     "the socket's colour is used")
            return None
        found = _follow(node.inputs["Vector"])
        if found is not None and not (found[0].bl_idname == "ShaderNodeUVMap" or (
                found[0].bl_idname == "ShaderNodeTexCoord" and found[1].name == "UV")):
            self.notes.warn(subject, f"image texture {node.name!r} is mapped through {found[0].bl_label!r}: "
                                     "read through the mesh's UVs instead")
        if node.projection != "FLAT":
            self.notes.warn(subject, f"image texture {node.name!r} uses {node.projection.lower()} "
                                     "projection: read through the mesh's UVs instead")
        if node.extension == "CLIP":
            self.notes.info(subject, f"image texture {node.name!r}: 'Clip' extension read as 'Extend'")
        if node.interpolation == "Closest":
            self.notes.info(subject, f"image texture {node.name!r}: 'Closest' interpolation is filtered "
                                     "(bilinear, mip-mapped) by the simulator")
        return self.image(node.image, subject)

    def image(self, image: bpy.types.Image, subject: str) -> ImageData | None:
        key = image.name_full
        if key in self.images:
            return self.images[key]
        width, height = int(image.size[0]), int(image.size[1])
        data: ImageData | None
        if width * height == 0 or image.channels == 0:
            self.notes.warn(subject, f"image {image.name!r} could not be loaded (missing file?)")
            data = None
        else:
            buf = np.empty(width * height * image.channels, np.float32)
            image.pixels.foreach_get(buf)
            px = buf.reshape(height, width, image.channels)[::-1]  # Blender's rows run bottom-up
            if image.is_float:
                data = ImageData(image.name, np.ascontiguousarray(px), "linear")
            else:
                space = image.colorspace_settings.name
                colorspace = "srgb" if space == "sRGB" else "linear"
                if space not in ("sRGB", "Non-Color", "Linear Rec.709", "Raw", "Linear"):
                    self.notes.info(subject, f"image {image.name!r} in colour space {space!r} read as "
                                             f"{colorspace}")
                data = ImageData(image.name, np.ascontiguousarray(np.round(px * 255.0).astype(np.uint8)),
                                 colorspace)
        self.images[key] = data
        return data

    def color_input(self, socket: bpy.types.NodeSocket, subject: str, label: str
                    ) -> tuple[float, float, float]:
        value = _constant(socket, self, subject, label)
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
        if arr.size == 1:
            arr = np.repeat(arr, 3)
        return (float(arr[0]), float(arr[1]), float(arr[2]))

    def float_input(self, socket: bpy.types.NodeSocket, subject: str, label: str) -> float:
        value = _constant(socket, self, subject, label)
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
        return float(arr[:3].mean()) if arr.size >= 3 else float(arr[0])

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
        inputs = self.world_inputs(world)
        env, strength, rotation = environment_from_inputs(inputs, self.notes)
        self.assembler.environment = env
        self.assembler.environment_strength = strength
        self.assembler.environment_rotation = rotation

    def world_inputs(self, world: bpy.types.World) -> WorldInputs:
        plain = WorldInputs(color=tuple(world.color[:3]))
        tree = world.node_tree
        if tree is None or not _uses_nodes(world):
            return plain
        output = _active_output(tree, "ShaderNodeOutputWorld")
        node = None if output is None else _linked_node(output.inputs["Surface"])
        if node is None:
            return WorldInputs(color=(0.0, 0.0, 0.0))
        if node.bl_idname != "ShaderNodeBackground":
            self.notes.warn("world", f"world shader {node.bl_label!r} is not a Background: its viewport "
                                     "colour is used")
            return plain
        strength = self.float_input(node.inputs["Strength"], "world", "Strength")
        color_socket = node.inputs["Color"]
        source = _linked_node(color_socket)
        if source is not None and source.bl_idname == "ShaderNodeTexEnvironment":
            return self.environment_texture(source, strength, color_socket)
        return WorldInputs(color=self.color_input(color_socket, "world", "Color"), strength=strength)

    def environment_texture(self, node: bpy.types.Node, strength: float, color_socket: Any) -> WorldInputs:
        if node.image is None:
            self.notes.warn("world", "environment texture without an image: Blender renders it pink; "
                                     "black used")
            return WorldInputs(color=(0.0, 0.0, 0.0), strength=strength)
        if node.projection != "EQUIRECTANGULAR":
            self.notes.warn("world", f"{node.projection.lower()} environment projection: approximated by the "
                                     "image's mean colour")
            image = self.image(node.image, "world")
            color = image.mean_linear_rgb() if image is not None else (0.0, 0.0, 0.0)
            return WorldInputs(color=color, strength=strength)
        rotation = self.mapping_rotation(node)
        image = self.image(node.image, "world")
        if image is None:
            return WorldInputs(color=(0.0, 0.0, 0.0), strength=strength)
        return WorldInputs(image=image, strength=strength, rotation_z=rotation)

    def mapping_rotation(self, env_node: bpy.types.Node) -> float:
        """Z rotation of a Mapping node feeding the environment texture (what Blender's HDRI set-ups use)."""
        mapping = _linked_node(env_node.inputs["Vector"])
        if mapping is None or mapping.bl_idname == "ShaderNodeTexCoord":
            return 0.0
        if mapping.bl_idname != "ShaderNodeMapping":
            self.notes.warn("world", f"environment vector from {mapping.bl_label!r} is not simulated: "
                                     "the default mapping is used")
            return 0.0
        rot = mapping.inputs["Rotation"]
        source = _follow(mapping.inputs["Vector"])
        if source is not None and not (source[0].bl_idname == "ShaderNodeTexCoord"
                                       and source[1].name == "Generated"):
            self.notes.warn("world", f"environment vector from {source[0].bl_label!r} is not simulated: "
                                     "the default mapping is used")
        if any(s.is_linked for s in mapping.inputs if s.name != "Vector"):
            self.notes.warn("world", "a linked Mapping input is not simulated: its unlinked values are used")
        rx, ry, rz = (float(v) for v in rot.default_value)
        scale = tuple(float(v) for v in mapping.inputs["Scale"].default_value)
        location = tuple(float(v) for v in mapping.inputs["Location"].default_value) \
            if mapping.vector_type in ("POINT", "TEXTURE") else (0.0, 0.0, 0.0)
        if abs(rx) > 1e-6 or abs(ry) > 1e-6 or any(abs(abs(s) - 1.0) > 1e-6 for s in scale) or \
                any(abs(v) > 1e-6 for v in location):
            self.notes.warn("world", "environment Mapping location, scale or rotation about X/Y is not "
                                     "simulated: only its Z rotation is used")
        return -rz if mapping.vector_type == "TEXTURE" else rz

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


# -- node-tree helpers ------------------------------------------------------------------------------------
def _uses_nodes(datablock: Any) -> bool:
    """Blender 5 always shades with the node tree (``use_nodes`` is deprecated there)."""
    return bpy.app.version >= (5, 0, 0) or bool(datablock.use_nodes)


def _active_output(tree: bpy.types.NodeTree, idname: str) -> bpy.types.Node | None:
    outputs = [n for n in tree.nodes
               if n.bl_idname == idname and getattr(n, "target", "ALL") in _OUTPUT_TARGETS]
    active = [n for n in outputs if n.is_active_output]
    return (active or outputs or [None])[0]


def _follow(socket: bpy.types.NodeSocket) -> tuple[bpy.types.Node, bpy.types.NodeSocket] | None:
    """The node and output socket feeding ``socket`` (through reroutes), None if unlinked or muted."""
    seen = 0
    while socket.is_linked and seen < 64:
        link = socket.links[0]
        if link.is_muted or not link.is_valid:
            return None
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            socket, seen = node.inputs[0], seen + 1
            continue
        if node.mute:
            return None
        return node, link.from_socket
    return None


def _linked_node(socket: bpy.types.NodeSocket) -> bpy.types.Node | None:
    found = _follow(socket)
    return None if found is None else found[0]


def _image_node(socket: bpy.types.NodeSocket) -> bpy.types.Node | None:
    """An Image Texture node whose Color output feeds ``socket`` directly (through reroutes)."""
    found = _follow(socket)
    if found is None:
        return None
    node, out = found
    return node if node.bl_idname == "ShaderNodeTexImage" and out.name == "Color" else None


def _constant(socket: bpy.types.NodeSocket, reader: _Reader, subject: str, label: str, depth: int = 0) -> Any:
    """A socket's value as a constant: its own value if unlinked, else a mean estimate of what feeds it
    (noted as an approximation)."""
    found = _follow(socket) if depth < 16 else None
    if found is None:
        return _socket_value(socket)
    node, out = found
    kind = node.bl_idname
    if kind in ("ShaderNodeRGB", "ShaderNodeValue"):
        return _socket_value(out)
    note = f"{label} driven by {node.bl_label!r}"
    if kind == "ShaderNodeTexImage" and node.image is not None:
        image = reader.image(node.image, subject)
        if image is not None:
            reader.notes.warn(subject, f"{note}: approximated by the image's mean")
            if out.name == "Alpha":
                px = image.pixels
                a = px[..., 3] if px.shape[-1] == 4 else np.ones(px.shape[:2])
                return float(np.mean(a / 255.0 if px.dtype == np.uint8 else a))
            return image.mean_linear_rgb()
    if kind == "ShaderNodeTexChecker":
        reader.notes.warn(subject, f"{note}: approximated by the mean of its two colours")
        c1 = np.asarray(_constant(node.inputs["Color1"], reader, subject, label, depth + 1), dtype=np.float64)
        c2 = np.asarray(_constant(node.inputs["Color2"], reader, subject, label, depth + 1), dtype=np.float64)
        return tuple(((c1[:3] + c2[:3]) / 2).tolist())
    if kind == "ShaderNodeValToRGB":
        elements = node.color_ramp.elements
        reader.notes.warn(subject, f"{note}: approximated by the mean of its colour stops")
        mean = np.mean([list(e.color[:3]) for e in elements], axis=0)
        return tuple(mean.tolist()) if out.name == "Color" else float(np.mean([e.color[3] for e in elements]))
    if kind == "ShaderNodeMix" and getattr(node, "data_type", "") == "RGBA" and node.blend_type == "MIX":
        reader.notes.info(subject, f"{note}: a mix of its inputs' means")
        fac = float(np.mean(_constant(_input(node, "Factor_Float"), reader, subject, label, depth + 1)))
        a, b = (np.asarray(_constant(_input(node, side), reader, subject, label, depth + 1), dtype=np.float64)
                for side in ("A_Color", "B_Color"))
        return tuple(((1 - fac) * a.reshape(-1)[:3] + fac * b.reshape(-1)[:3]).tolist())
    reader.notes.warn(subject, f"{note} (a procedural or unsupported node set-up): approximated by the "
                               "socket's own value")
    return _socket_value(socket)


def _input(node: bpy.types.Node, identifier: str) -> bpy.types.NodeSocket:
    return next(s for s in node.inputs if s.identifier == identifier)


def _socket_value(socket: bpy.types.NodeSocket) -> Any:
    value = getattr(socket, "default_value", None)
    if value is None:
        return 0.0
    try:
        return tuple(float(v) for v in value)
    except TypeError:
        return float(value)
