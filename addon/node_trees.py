"""Material and world node trees as plain inputs for the translator: the Principled BSDF (and the few
other shaders it approximates), Image Texture nodes and their pixels, the world's Background and
Environment Texture with its Mapping rotation. A link that cannot be followed is reduced to a constant
(a mean estimate of what feeds the socket) with a note saying so. Reads bpy; the conversions to the
simulator's values live in ``core/scene_translation``.
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np

from .core.scene_translation import ImageData, MaterialInputs, Notes, WorldInputs
from .core.scene_translation.cache import Cached

_OUTPUT_TARGETS = ("ALL", "CYCLES")
_WRAPS = {"REPEAT": "repeat", "EXTEND": "clamp", "CLIP": "clamp", "MIRROR": "mirror"}


class NodeTreeReader:
    """Reads materials, images and the world through their node trees; each image is read once."""

    def __init__(self, notes: Notes) -> None:
        self.notes = notes
        # image pixels by image name, with the notes reading them made (replayed on each use, so a table
        # kept across translations, as the viewport's is, gives the same notes as a fresh read)
        self.images: dict[str, Cached[ImageData | None]] = {}

    # materials ----------------------------------------------------------------------------------------
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
        cached = self.images.get(key)
        if cached is None:
            outer, self.notes = self.notes, Notes()
            try:
                cached = Cached(self._read_image(image, subject), tuple(self.notes))
            finally:
                self.notes = outer
            self.images[key] = cached
        return cached.replay(self.notes)

    def _read_image(self, image: bpy.types.Image, subject: str) -> ImageData | None:
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

    # world --------------------------------------------------------------------------------------------
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


def _constant(socket: bpy.types.NodeSocket, reader: NodeTreeReader, subject: str, label: str,
              depth: int = 0) -> Any:
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
