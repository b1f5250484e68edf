"""The glTF document: the GLB container or JSON text, its buffers, and the one policy for the files and
URIs it refers to (:func:`referenced_file`), checked for every reference before any of them is read."""

from __future__ import annotations

import base64
import json
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote, unquote_to_bytes

from ..confined import confined_path, shown

_GLB_MAGIC = 0x46546C67  # b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
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
#: Scene extras key the blend_scenes generators use to name an environment (EXR path or RGB colour).
ENVIRONMENT_EXTRAS_KEY = "render_budget_environment"
#: A URI scheme ("http:", "file:", a Windows drive letter): never a file next to the scene.
_URI_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


@dataclass
class Document:
    gltf: dict[str, Any]
    buffers: list[bytes]
    path: Path
    self_contained: bool


def read_document(path: Path, *, self_contained: bool) -> Document:
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

    doc = Document(gltf, [], path, self_contained)
    for what, uri in _references(gltf):  # every reference obeys the policy before anything is read
        referenced_file(doc, uri, what)
    for i, buf in enumerate(gltf.get("buffers", [])):
        byte_length = int(buf.get("byteLength", 0))
        uri = buf.get("uri")
        if uri is None:
            if i != 0 or bin_chunk is None:
                raise ValueError(f"{path}: buffer {i} has no uri and there is no GLB binary chunk")
            blob = bin_chunk
        else:
            blob = referenced_bytes(doc, uri, f"buffer {i}")
        if len(blob) < byte_length:
            raise ValueError(f"{path}: buffer {i} truncated ({len(blob)} bytes, expected {byte_length})")
        doc.buffers.append(blob[:byte_length])
    return doc


def _references(gltf: dict[str, Any]) -> list[tuple[str, Any]]:
    """(what, reference) for everything outside the document's own bytes that loading may read."""
    refs: list[tuple[str, Any]] = [(f"buffer {i}", b["uri"]) for i, b in enumerate(gltf.get("buffers", []))
                                   if isinstance(b, dict) and "uri" in b]
    refs += [(f"image {i}", im["uri"]) for i, im in enumerate(gltf.get("images", []))
             if isinstance(im, dict) and "uri" in im and "bufferView" not in im]
    environment = environment_extra(gltf)
    if isinstance(environment, str):
        refs.append(("environment map", environment))
    return refs


def referenced_file(doc: Document, uri: Any, what: str) -> Path | None:
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


def referenced_bytes(doc: Document, uri: Any, what: str) -> bytes:
    file = referenced_file(doc, uri, what)
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


def environment_extra(gltf: dict[str, Any]) -> Any:
    scenes = gltf.get("scenes", [])
    if not scenes:
        return None
    extras = scenes[int(gltf.get("scene", 0))].get("extras") or {}
    return extras.get(ENVIRONMENT_EXTRAS_KEY) if isinstance(extras, dict) else None
