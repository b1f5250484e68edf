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
:func:`_referenced_file`, checked for every reference before any of them is read: with
``self_contained=True`` (scenes uploaded to the service) only the GLB binary chunk and ``data:`` URIs
are allowed; otherwise relative files are read, but only inside the scene file's own folder (resolved
paths, so neither ``..`` nor a symbolic link leads out). Error messages name the reference as the file
wrote it, never a resolved path or the bytes of another file.
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote, unquote_to_bytes

import numpy as np
from PIL import Image

from ..geometry import smooth_normals
from ..image import load_exr
from ..scene_data import CameraData, Light, Material, SceneData, Texture
from .confined import confined_path, shown

#: glTF (Y-up) to Blender (Z-up) world frame: (x, y, z) -> (x, -z, y).
GLTF_TO_BLENDER = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
#: Luminous efficacy Blender's glTF exporter assumes ('SPEC' mode): lm per W.
LUMENS_PER_WATT = 683.0

_GLB_MAGIC = 0x46546C67  # b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942

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
_SUPPORTED_REQUIRED = {
    "KHR_lights_punctual",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_materials_specular",
    "KHR_materials_volume",
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_materials_unlit",
    "KHR_texture_transform",
    "KHR_mesh_quantization",
    "EXT_mesh_gpu_instancing",
    "EXT_texture_webp",
}
#: Upper bound on any accessor's element count (a hostile count must not allocate gigabytes).
_MAX_ELEMENTS = 1 << 28
#: Scene extras key the blend_scenes generators use to name an environment (EXR path or RGB colour).
ENVIRONMENT_EXTRAS_KEY = "render_budget_environment"
#: Light extras key for the emitter size glTF cannot express: radius in metres for point and spot lights,
#: angular radius in radians for sun lights (Blender's shadow_soft_size, and half its sun angle).
LIGHT_RADIUS_EXTRAS_KEY = "render_budget_radius"
#: Largest texture side the loader keeps; bigger images are downscaled (with a warning) when decoded.
MAX_LOADED_TEXTURE_SIDE = 8192
_WRAPS = {10497: "repeat", 33071: "clamp", 33648: "mirror"}
_ALPHA_MODES = {"OPAQUE": "opaque", "MASK": "clip", "BLEND": "hashed"}
#: A URI scheme ("http:", "file:", a Windows drive letter): never a file next to the scene.
_URI_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


@dataclass
class _Document:
    gltf: dict[str, Any]
    buffers: list[bytes]
    path: Path
    self_contained: bool


# --------------------------------------------------------------------------------------------------
# Container
# --------------------------------------------------------------------------------------------------


def _read_document(path: Path, *, self_contained: bool) -> _Document:
    if not path.is_file():
        raise FileNotFoundError(f"glTF file not found: {path}")
    data = path.read_bytes()
    bin_chunk: bytes | None = None
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise ValueError(f"{path}: truncated GLB header")
        magic, version, length = struct.unpack_from("<III", data, 0)
        if magic != _GLB_MAGIC:
            raise ValueError(f"{path}: not a GLB file")
        if version != 2:
            raise ValueError(f"{path}: GLB version {version} is not supported (only 2)")
        if length > len(data):
            raise ValueError(f"{path}: truncated GLB ({len(data)} bytes, header says {length})")
        offset = 12
        json_chunk: bytes | None = None
        while offset + 8 <= length:
            chunk_len, chunk_type = struct.unpack_from("<II", data, offset)
            start, end = offset + 8, offset + 8 + chunk_len
            if end > length:
                raise ValueError(f"{path}: truncated GLB chunk at byte {offset}")
            if chunk_type == _CHUNK_JSON and json_chunk is None:
                json_chunk = data[start:end]
            elif chunk_type == _CHUNK_BIN and bin_chunk is None:
                bin_chunk = data[start:end]
            offset = end + ((4 - chunk_len % 4) % 4 if end < length else 0)
        if json_chunk is None:
            raise ValueError(f"{path}: GLB has no JSON chunk")
        text = json_chunk
    else:
        text = data
    try:
        gltf = json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a glTF file (JSON does not parse: {exc})") from None
    if not isinstance(gltf, dict) or "asset" not in gltf:
        raise ValueError(f"{path}: not a glTF file (no 'asset' object)")
    version = str(gltf["asset"].get("version", ""))
    if not version.startswith("2."):
        raise ValueError(f"{path}: glTF version {version!r} is not supported (only 2.x)")
    unsupported = set(gltf.get("extensionsRequired", [])) - _SUPPORTED_REQUIRED
    if unsupported:
        raise ValueError(f"{path}: requires unsupported glTF extensions {sorted(unsupported)}")

    doc = _Document(gltf, [], path, self_contained)
    for what, uri in _references(gltf):  # every reference obeys the policy before anything is read
        _referenced_file(doc, uri, what)
    for i, buf in enumerate(gltf.get("buffers", [])):
        byte_length = int(buf.get("byteLength", 0))
        uri = buf.get("uri")
        if uri is None:
            if i != 0 or bin_chunk is None:
                raise ValueError(f"{path}: buffer {i} has no uri and there is no GLB binary chunk")
            blob = bin_chunk
        else:
            blob = _referenced_bytes(doc, uri, f"buffer {i}")
        if len(blob) < byte_length:
            raise ValueError(f"{path}: buffer {i} truncated ({len(blob)} bytes, expected {byte_length})")
        doc.buffers.append(blob[:byte_length])
    return doc


# --------------------------------------------------------------------------------------------------
# Files and URIs the document refers to
# --------------------------------------------------------------------------------------------------


def _references(gltf: dict[str, Any]) -> list[tuple[str, Any]]:
    """(what, reference) for everything outside the document's own bytes that loading may read."""
    refs: list[tuple[str, Any]] = [(f"buffer {i}", b["uri"]) for i, b in enumerate(gltf.get("buffers", []))
                                   if isinstance(b, dict) and "uri" in b]
    refs += [(f"image {i}", im["uri"]) for i, im in enumerate(gltf.get("images", []))
             if isinstance(im, dict) and "uri" in im and "bufferView" not in im]
    environment = _environment_extra(gltf)
    if isinstance(environment, str):
        refs.append(("environment map", environment))
    return refs


def _referenced_file(doc: _Document, uri: Any, what: str) -> Path | None:
    """The one policy for data outside the document (buffers, images, the environment map): None for a
    ``data:`` URI (its bytes are in the document), else the confined path of a relative file. Nothing is
    read here; raises ValueError naming the reference when the policy forbids it."""
    if not isinstance(uri, str) or not uri:
        raise ValueError(f"{doc.path}: {what} has an empty or non-text uri")
    if uri.startswith("data:"):
        return None
    if doc.self_contained:
        raise ValueError(
            f"{doc.path}: {what} refers to the external file {shown(uri)}: an uploaded scene must be "
            "self-contained (a .glb with its binary chunk, or data: URIs)")
    if _URI_SCHEME.match(uri):
        raise ValueError(f"{doc.path}: {what} uri {shown(uri)} is not a relative file reference")
    try:
        return confined_path(doc.path.parent, unquote(uri))
    except ValueError as exc:
        raise ValueError(f"{doc.path}: {what} uri {exc}") from None


def _referenced_bytes(doc: _Document, uri: Any, what: str) -> bytes:
    file = _referenced_file(doc, uri, what)
    if file is None:
        head, comma, payload = uri.partition(",")
        if not comma:
            raise ValueError(f"{doc.path}: {what} has a bad data URI (no comma)")
        try:
            return base64.b64decode(payload) if head.endswith(";base64") else unquote_to_bytes(payload)
        except ValueError as exc:
            raise ValueError(f"{doc.path}: {what} has a bad data URI ({exc})") from None
    if not file.is_file():
        raise FileNotFoundError(f"{doc.path}: {what} file {shown(uri)} not found next to the scene")
    return file.read_bytes()


# --------------------------------------------------------------------------------------------------
# Accessors
# --------------------------------------------------------------------------------------------------


def _buffer_view_bytes(doc: _Document, index: int) -> tuple[memoryview, int | None]:
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


def _read_accessor(doc: _Document, index: int) -> np.ndarray:
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
        raw, stride = _buffer_view_bytes(doc, int(acc["bufferView"]))
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
        raw_i, _ = _buffer_view_bytes(doc, int(sidx["bufferView"]))
        idx = _strided(raw_i, int(sidx.get("byteOffset", 0)), scount, 1, _COMPONENT_DTYPES[itype], None,
                       what + " sparse indices")[:, 0].astype(np.int64)
        if scount and (idx.min() < 0 or idx.max() >= count):
            raise ValueError(f"{what}: sparse index out of range [0, {count})")
        svals = sparse["values"]
        raw_v, _ = _buffer_view_bytes(doc, int(svals["bufferView"]))
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


# --------------------------------------------------------------------------------------------------
# Nodes
# --------------------------------------------------------------------------------------------------


def _quat_to_matrix(q: list[float]) -> np.ndarray:
    x, y, z, w = (float(c) for c in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n == 0.0 or not math.isfinite(n):
        raise ValueError(f"node rotation quaternion {q} is invalid")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _local_matrix(node: dict[str, Any]) -> np.ndarray:
    if "matrix" in node:
        m = np.asarray(node["matrix"], dtype=np.float64)
        if m.shape != (16,):
            raise ValueError(f"node matrix must have 16 numbers, got {m.shape}")
        m = m.reshape(4, 4).T  # glTF stores column-major
    else:
        t = np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
        r = _quat_to_matrix(node.get("rotation", [0.0, 0.0, 0.0, 1.0]))
        s = np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
        if t.shape != (3,) or s.shape != (3,):
            raise ValueError("node translation and scale must have 3 numbers")
        m = np.eye(4)
        m[:3, :3] = r * s[None, :]
        m[:3, 3] = t
    if not np.all(np.isfinite(m)):
        raise ValueError(f"node {node.get('name', '')!r} has a non-finite transform")
    return m


def _walk_nodes(doc: _Document) -> list[tuple[int, np.ndarray]]:
    """(node index, world matrix in the glTF frame) for every node of the default scene, depth first."""
    gltf = doc.gltf
    nodes = gltf.get("nodes", [])
    scenes = gltf.get("scenes", [])
    if scenes:
        scene_index = int(gltf.get("scene", 0))
        if not 0 <= scene_index < len(scenes):
            raise ValueError(f"{doc.path}: default scene {scene_index} does not exist")
        roots = list(scenes[scene_index].get("nodes", []))
    else:  # no scene: every node that is nobody's child is a root
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    out: list[tuple[int, np.ndarray]] = []
    seen: set[int] = set()
    stack = [(int(r), np.eye(4)) for r in reversed(roots)]
    while stack:
        index, parent = stack.pop()
        if not 0 <= index < len(nodes):
            raise ValueError(f"{doc.path}: node {index} does not exist")
        if index in seen:
            raise ValueError(f"{doc.path}: node {index} appears twice in the hierarchy (cycle or shared)")
        seen.add(index)
        world = parent @ _local_matrix(nodes[index])
        out.append((index, world))
        for child in reversed(nodes[index].get("children", [])):
            stack.append((int(child), world))
    return out


# --------------------------------------------------------------------------------------------------
# Meshes, materials, lights, cameras
# --------------------------------------------------------------------------------------------------


def _primitive_triangles(doc: _Document, prim: dict[str, Any], vcount: int, what: str) -> np.ndarray | None:
    mode = int(prim.get("mode", 4))
    if mode not in (4, 5, 6):
        return None  # points and lines hold no surface
    if "indices" in prim:
        idx = _read_accessor(doc, int(prim["indices"]))
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


def _image_bytes(doc: _Document, image_index: int) -> bytes:
    images = doc.gltf.get("images", [])
    if not 0 <= image_index < len(images):
        raise ValueError(f"{doc.path}: image {image_index} does not exist")
    img = images[image_index]
    if "bufferView" in img:
        raw, _ = _buffer_view_bytes(doc, int(img["bufferView"]))
        return bytes(raw)
    if "uri" not in img:
        raise ValueError(f"{doc.path}: image {image_index} has neither a bufferView nor a uri")
    return _referenced_bytes(doc, img["uri"], f"image {image_index}")


@dataclass
class _BaseColorTexture:
    """How a material samples its base-colour texture: which SceneData texture, which TEXCOORD set, and
    the KHR_texture_transform (3x3, in glTF's UV space) applied to those coordinates."""

    texture: int
    texcoord: int
    transform: np.ndarray | None


class _TextureTable:
    """Base-colour textures of a document: each image decoded once, one Texture per (image, wrap modes)."""

    def __init__(self, doc: _Document) -> None:
        self.doc = doc
        self.textures: list[Texture] = []
        self._index: dict[tuple[int, str, str], int] = {}
        self._images: dict[int, np.ndarray] = {}

    def texture(self, texture_index: int) -> int | None:
        """SceneData texture index of glTF texture ``texture_index`` (None: no decodable source)."""
        doc = self.doc
        textures = doc.gltf.get("textures", [])
        if not 0 <= texture_index < len(textures):
            raise ValueError(f"{doc.path}: texture {texture_index} does not exist")
        tex = textures[texture_index]
        source = tex.get("source")
        extensions = tex.get("extensions", {})
        if "EXT_texture_webp" in extensions:  # Pillow decodes WebP
            source = extensions["EXT_texture_webp"].get("source", source)
        if source is None:
            if extensions:  # GPU-compressed only (KTX2/basisu, DDS): no decoder here, keep the factor alone
                return None
            raise ValueError(f"{doc.path}: texture {texture_index} has no image source")
        sampler: dict[str, Any] = {}
        if "sampler" in tex:
            samplers = doc.gltf.get("samplers", [])
            si = int(tex["sampler"])
            if not 0 <= si < len(samplers):
                raise ValueError(f"{doc.path}: texture {texture_index} refers to missing sampler {si}")
            sampler = samplers[si]
        wrap_u = _WRAPS.get(int(sampler.get("wrapS", 10497)), "repeat")
        wrap_v = _WRAPS.get(int(sampler.get("wrapT", 10497)), "repeat")
        key = (int(source), wrap_u, wrap_v)
        if key not in self._index:
            image = self._image(int(source))
            name = str(doc.gltf.get("images", [])[int(source)].get("name", f"image_{source}"))
            self._index[key] = len(self.textures)
            self.textures.append(Texture(image, colorspace="srgb", wrap_u=wrap_u, wrap_v=wrap_v, name=name))
        return self._index[key]

    def _image(self, source: int) -> np.ndarray:
        """(H, W, 3|4) uint8, sRGB-encoded (what glTF base-colour images are), row 0 at the top."""
        if source in self._images:
            return self._images[source]
        doc = self.doc
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", Image.DecompressionBombWarning)
                with Image.open(io.BytesIO(_image_bytes(doc, source))) as im:
                    alpha = im.mode in ("RGBA", "LA", "PA", "RGBa", "La") or "transparency" in im.info
                    rgb = im.convert("RGBA" if alpha else "RGB")
                    if max(rgb.size) > MAX_LOADED_TEXTURE_SIDE:
                        warnings.simplefilter("default")
                        size = f"{rgb.size[0]}x{rgb.size[1]}"
                        warnings.warn(f"{doc.path}: image {source} ({size}) downscaled to at most "
                                      f"{MAX_LOADED_TEXTURE_SIDE} texels a side", stacklevel=2)
                        rgb.thumbnail((MAX_LOADED_TEXTURE_SIDE, MAX_LOADED_TEXTURE_SIDE))
                    pixels = np.asarray(rgb, dtype=np.uint8)
        except (OSError, ValueError, Image.DecompressionBombWarning, Image.DecompressionBombError) as exc:
            raise ValueError(f"{doc.path}: texture image {source} cannot be decoded ({exc})") from None
        self._images[source] = pixels
        return pixels


def _uv_transform(info: dict[str, Any]) -> tuple[int, np.ndarray | None]:
    """(TEXCOORD set, KHR_texture_transform matrix or None) of a textureInfo."""
    texcoord = int(info.get("texCoord", 0))
    ext = info.get("extensions", {}).get("KHR_texture_transform")
    if not isinstance(ext, dict):
        return texcoord, None
    texcoord = int(ext.get("texCoord", texcoord))
    ox, oy = (float(c) for c in ext.get("offset", [0.0, 0.0]))
    sx, sy = (float(c) for c in ext.get("scale", [1.0, 1.0]))
    r = float(ext.get("rotation", 0.0))
    c, s = math.cos(r), math.sin(r)
    translation = np.array([[1, 0, ox], [0, 1, oy], [0, 0, 1]])
    rotation = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    m = translation @ rotation @ np.diag([sx, sy, 1.0])
    if not np.all(np.isfinite(m)):
        raise ValueError(f"KHR_texture_transform must be finite, got {ext!r}")
    return texcoord, m


def _material(doc: _Document, index: int, table: _TextureTable) -> tuple[Material, _BaseColorTexture | None]:
    mats = doc.gltf.get("materials", [])
    if not 0 <= index < len(mats):
        raise ValueError(f"{doc.path}: material {index} does not exist")
    m = mats[index]
    pbr = m.get("pbrMetallicRoughness", {})
    ext = m.get("extensions", {})
    factor = list(pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0]))
    base = np.asarray(factor[:3], dtype=np.float64)
    alpha = float(factor[3]) if len(factor) > 3 else 1.0
    sampling = None
    if "baseColorTexture" in pbr:
        info = pbr["baseColorTexture"]
        texture = table.texture(int(info["index"]))
        if texture is not None:
            texcoord, transform = _uv_transform(info)
            sampling = _BaseColorTexture(texture, texcoord, transform)
    emissive = np.asarray(m.get("emissiveFactor", [0.0, 0.0, 0.0]), dtype=np.float64)
    emissive = emissive * float(ext.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0))
    transmission = float(ext.get("KHR_materials_transmission", {}).get("transmissionFactor", 0.0))
    ior = float(ext.get("KHR_materials_ior", {}).get("ior", 1.5))
    if ior == 0.0:  # KHR_materials_ior: 0 means "no refraction info"; keep the default
        ior = 1.5
    mode = str(m.get("alphaMode", "OPAQUE"))
    if mode not in _ALPHA_MODES:
        raise ValueError(f"{doc.path}: material {index} has unknown alphaMode {mode!r}")
    material = Material(
        base_color=tuple(float(np.clip(c, 0.0, 1.0)) for c in base),
        metallic=float(np.clip(pbr.get("metallicFactor", 1.0), 0.0, 1.0)),
        roughness=float(np.clip(pbr.get("roughnessFactor", 1.0), 0.0, 1.0)),
        transmission=float(np.clip(transmission, 0.0, 1.0)),
        ior=float(np.clip(ior, 1.0, 4.0)),
        emission=tuple(float(c) for c in emissive),
        name=str(m.get("name", f"material_{index}")),
        alpha=float(np.clip(alpha, 0.0, 1.0)),
        alpha_mode=_ALPHA_MODES[mode],  # type: ignore[arg-type]
        alpha_cutoff=float(np.clip(m.get("alphaCutoff", 0.5), 0.0, 1.0)),
        base_color_texture=None if sampling is None else sampling.texture,
    )
    return material, sampling


def _primitive_uvs(doc: _Document, attrs: dict[str, Any], sampling: _BaseColorTexture, count: int,
                   what: str) -> np.ndarray:
    """Blender-convention UVs (v up) of a primitive's vertices for its material's base-colour texture;
    zeros when the primitive lacks that TEXCOORD set."""
    key = f"TEXCOORD_{sampling.texcoord}"
    if key not in attrs:
        return np.zeros((count, 2))
    uv = _read_accessor(doc, int(attrs[key])).astype(np.float64)
    if uv.shape != (count, 2):
        raise ValueError(f"{what}: {key} must be VEC2 with one entry per vertex, got {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise ValueError(f"{what}: {key} contains NaN or Inf")
    if sampling.transform is not None:
        uv = uv @ sampling.transform[:2, :2].T + sampling.transform[:2, 2]
    return np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)


def _light(doc: _Document, index: int, world_b: np.ndarray, name: str) -> Light:
    lights = doc.gltf.get("extensions", {}).get("KHR_lights_punctual", {}).get("lights", [])
    if not 0 <= index < len(lights):
        raise ValueError(f"{doc.path}: light {index} does not exist")
    src = lights[index]
    gtype = src.get("type")
    kinds = {"point": "POINT", "spot": "SPOT", "directional": "SUN"}
    if gtype not in kinds:
        raise ValueError(f"{doc.path}: light {index} has unknown type {gtype!r}")
    spot = src.get("spot", {})
    extras = src.get("extras") if isinstance(src.get("extras"), dict) else {}
    radius = float(extras.get(LIGHT_RADIUS_EXTRAS_KEY, 0.0))
    intensity = float(src.get("intensity", 1.0)) / LUMENS_PER_WATT  # W/sr (point, spot) or W/m^2 (sun)
    outer = float(spot.get("outerConeAngle", math.pi / 4))
    inner = float(spot.get("innerConeAngle", 0.0))
    blend = float(np.clip(1.0 - inner / outer, 0.0, 1.0)) if outer > 0 else 0.0
    # Lights shine down their local -Z in glTF and in Blender alike; from_blender reads that off world_b.
    return Light.from_blender(
        kinds[gtype],
        world_b,
        intensity if gtype == "directional" else intensity * 4.0 * math.pi,
        tuple(float(c) for c in src.get("color", [1.0, 1.0, 1.0])),
        shadow_soft_size=radius if gtype != "directional" else 0.0,
        angle=2.0 * radius if gtype == "directional" else 0.0,
        spot_size=2.0 * outer,
        spot_blend=blend,
        name=str(src.get("name", name)),
    )


def _environment_extra(gltf: dict[str, Any]) -> Any:
    scenes = gltf.get("scenes", [])
    if not scenes:
        return None
    extras = scenes[int(gltf.get("scene", 0))].get("extras") or {}
    return extras.get(ENVIRONMENT_EXTRAS_KEY) if isinstance(extras, dict) else None


def _environment(doc: _Document) -> np.ndarray | tuple[float, float, float] | None:
    value = _environment_extra(doc.gltf)
    if value is None:
        return None
    if isinstance(value, str):
        exr = _referenced_file(doc, value, "environment map")
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


def _gpu_instances(doc: _Document, ext: dict[str, Any], what: str) -> list[np.ndarray]:
    """EXT_mesh_gpu_instancing: per-instance local matrices (T * R * S) from its attribute accessors."""
    attrs = ext.get("attributes", {})
    if not attrs:
        raise ValueError(f"{doc.path}: {what}: EXT_mesh_gpu_instancing without attributes")
    arrays = {k: _read_accessor(doc, int(v)).astype(np.float64) for k, v in attrs.items()
              if k in ("TRANSLATION", "ROTATION", "SCALE")}
    counts = {a.shape[0] for a in arrays.values()}
    if len(counts) != 1:
        raise ValueError(f"{doc.path}: {what}: instance attributes differ in count")
    n = counts.pop()
    t = arrays.get("TRANSLATION", np.zeros((n, 3)))
    r = arrays.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    sc = arrays.get("SCALE", np.ones((n, 3)))
    if t.shape[1] != 3 or r.shape[1] != 4 or sc.shape[1] != 3:
        raise ValueError(f"{doc.path}: {what}: instance attributes have the wrong types")
    out = []
    for k in range(n):
        m = np.eye(4)
        m[:3, :3] = _quat_to_matrix(list(r[k])) * sc[k][None, :]
        m[:3, 3] = t[k]
        if not np.all(np.isfinite(m)):
            raise ValueError(f"{doc.path}: {what}: instance {k} has a non-finite transform")
        out.append(m)
    return out


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


# Long: one walk over the node hierarchy filling per-primitive parts (positions, normals, ids) that are
# concatenated at the end; the module (over 500 lines) is the one glTF reader, helpers included.
def _load(p: Path, self_contained: bool) -> SceneData:
    doc = _read_document(p, self_contained=self_contained)
    gltf = doc.gltf
    nodes = gltf.get("nodes", [])
    meshes = gltf.get("meshes", [])

    table = _TextureTable(doc)
    decoded_materials = [_material(doc, i, table) for i in range(len(gltf.get("materials", [])))]
    materials = [m for m, _ in decoded_materials]
    samplings = [t for _, t in decoded_materials]
    default_material: int | None = None
    pos_parts: list[np.ndarray] = []
    nrm_parts: list[np.ndarray | None] = []
    uv_parts: list[np.ndarray | None] = []
    tri_parts: list[np.ndarray] = []
    mat_parts: list[np.ndarray] = []
    obj_parts: list[np.ndarray] = []
    object_names: list[str] = []
    lights: list[Light] = []
    cameras: list[CameraData] = []
    vbase = 0
    decoded: dict[int, tuple[np.ndarray, np.ndarray | None]] = {}

    for node_index, world_g in _walk_nodes(doc):
        node = nodes[node_index]
        name = str(node.get("name", f"node_{node_index}"))
        world_b = GLTF_TO_BLENDER @ world_g
        ext = node.get("extensions", {})
        if "KHR_lights_punctual" in ext:
            lights.append(_light(doc, int(ext["KHR_lights_punctual"]["light"]), world_b, name))
        if "camera" in node:
            cams = gltf.get("cameras", [])
            ci = int(node["camera"])
            if not 0 <= ci < len(cams):
                raise ValueError(f"{doc.path}: camera {ci} does not exist")
            persp = cams[ci].get("perspective")
            if persp is not None:  # orthographic cameras are not modelled
                yfov = float(persp["yfov"])
                aspect = float(persp.get("aspectRatio", 16 / 9))
                if not (0.0 < yfov < math.pi):
                    raise ValueError(f"{doc.path}: camera {ci} yfov {yfov} outside (0, pi)")
                if not (math.isfinite(aspect) and aspect > 0.0):
                    raise ValueError(f"{doc.path}: camera {ci} aspectRatio {aspect} must be positive")
                cameras.append(CameraData(matrix_world=world_b.copy(), vfov=yfov, aspect=aspect, name=name))
        if "mesh" not in node:
            continue
        mi = int(node["mesh"])
        if not 0 <= mi < len(meshes):
            raise ValueError(f"{doc.path}: mesh {mi} does not exist")
        instancing = ext.get("EXT_mesh_gpu_instancing")
        placements = [(name, world_b)]
        if instancing is not None:  # one object per GPU instance: node world @ instance TRS
            placements = [(f"{name}.{k}", world_b @ m)
                          for k, m in enumerate(_gpu_instances(doc, instancing, f"node {name!r}"))]
        for name_k, world_k in placements:
            object_id = len(object_names)
            object_names.append(name_k)
            m3 = world_k[:3, :3]
            # Inverse transpose up to a positive scale (normals are renormalised): the cofactor matrix
            # times the determinant's sign; closed form (np.linalg.inv is slow on many small matrices).
            c0, c1, c2 = m3[:, 0], m3[:, 1], m3[:, 2]
            cof = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=1)
            det = float(np.dot(c0, cof[:, 0]))
            # A zero scale (hidden object) makes every triangle degenerate: kept; the core drops them.
            normal_matrix = cof * math.copysign(1.0, det)
            mirrored = det < 0.0
            for pi, prim in enumerate(meshes[mi].get("primitives", [])):
                what = f"{doc.path}: mesh {mi} ({meshes[mi].get('name', '')!r}) primitive {pi}"
                attrs = prim.get("attributes", {})
                if "POSITION" not in attrs:
                    raise ValueError(f"{what}: no POSITION attribute")
                key = id(prim)
                if key not in decoded:
                    pos = _read_accessor(doc, int(attrs["POSITION"]))
                    if pos.shape[1] != 3:
                        raise ValueError(f"{what}: POSITION must be VEC3")
                    pos = pos.astype(np.float64)
                    if not np.all(np.isfinite(pos)):
                        raise ValueError(f"{what}: POSITION contains NaN or Inf")
                    nrm = None
                    if "NORMAL" in attrs:
                        nrm = _read_accessor(doc, int(attrs["NORMAL"])).astype(np.float64)
                        if nrm.shape != pos.shape:
                            raise ValueError(f"{what}: NORMAL count/shape differs from POSITION")
                        if not np.all(np.isfinite(nrm)):
                            raise ValueError(f"{what}: NORMAL contains NaN or Inf")
                    decoded[key] = (pos, nrm)
                pos, nrm = decoded[key]
                tris = _primitive_triangles(doc, prim, pos.shape[0], what)
                if tris is None or tris.shape[0] == 0:
                    continue
                world_pos = pos @ m3.T + world_k[:3, 3]
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
                if "material" in prim:
                    mat = int(prim["material"])
                    if not 0 <= mat < len(materials):
                        raise ValueError(f"{what}: material {mat} does not exist")
                else:
                    if default_material is None:
                        default_material = len(materials)
                        materials.append(Material(name="default"))
                    mat = default_material
                sampling = samplings[mat] if mat < len(samplings) else None
                pos_parts.append(world_pos)
                nrm_parts.append(wn)
                uv_parts.append(None if sampling is None
                                else _primitive_uvs(doc, attrs, sampling, world_pos.shape[0], what))
                tri_parts.append(tris + vbase)
                mat_parts.append(np.full(tris.shape[0], mat, dtype=np.uint32))
                obj_parts.append(np.full(tris.shape[0], object_id, dtype=np.uint32))
                vbase += world_pos.shape[0]

    if not tri_parts:
        raise ValueError(f"{doc.path}: the scene contains no triangles (empty scene)")

    positions = np.concatenate(pos_parts)
    triangles = np.concatenate(tri_parts)
    normals: np.ndarray | None = None
    if any(n is not None for n in nrm_parts):
        filled = []
        starts = np.cumsum([0] + [part.shape[0] for part in pos_parts[:-1]])
        for part_pos, part_nrm, part_tri, start in zip(pos_parts, nrm_parts, tri_parts, starts, strict=True):
            filled.append(part_nrm if part_nrm is not None else smooth_normals(part_pos, part_tri - start))
        normals = np.concatenate(filled).astype(np.float32)
    uvs: np.ndarray | None = None
    if any(u is not None for u in uv_parts):  # UVs only when some textured material is drawn
        uvs = np.concatenate([u if u is not None else np.zeros((part.shape[0], 2))
                              for u, part in zip(uv_parts, pos_parts, strict=True)]).astype(np.float32)
    if positions.shape[0] > np.iinfo(np.uint32).max:
        raise ValueError(f"{doc.path}: too many vertices for 32-bit indices")
    return SceneData(
        positions=positions.astype(np.float32),
        triangles=triangles.astype(np.uint32),
        normals=normals,
        material_ids=np.concatenate(mat_parts),
        object_ids=np.concatenate(obj_parts),
        materials=materials,
        lights=lights,
        cameras=cameras,
        environment=_environment(doc),
        source=str(p),
        object_names=object_names,
        uvs=uvs,
        textures=table.textures,
    )
