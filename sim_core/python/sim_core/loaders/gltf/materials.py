"""glTF materials as the simulator's: metallic-roughness factors, the KHR material extensions, alpha
modes, and base-colour textures (one decoded image per texture and sampler, shared by every material using
it; KHR_texture_transform baked into the UVs, which are flipped to Blender's v-up convention)."""

from __future__ import annotations

import io
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from PIL import Image

from ...scene_data import Material, Texture
from .accessors import buffer_view_bytes, read_accessor
from .document import Document, referenced_bytes

#: Largest texture side the loader keeps; bigger images are downscaled (with a warning) when decoded.
MAX_LOADED_TEXTURE_SIDE = 8192
_WRAPS = {10497: "repeat", 33071: "clamp", 33648: "mirror"}
_ALPHA_MODES = {"OPAQUE": "opaque", "MASK": "clip", "BLEND": "hashed"}


def _image_bytes(doc: Document, image_index: int) -> bytes:
    images = doc.gltf.get("images", [])
    if not 0 <= image_index < len(images):
        raise ValueError(f"{doc.path}: image {image_index} does not exist")
    img = images[image_index]
    if "bufferView" in img:
        raw, _ = buffer_view_bytes(doc, int(img["bufferView"]))
        return bytes(raw)
    if "uri" not in img:
        raise ValueError(f"{doc.path}: image {image_index} has neither a bufferView nor a uri")
    return referenced_bytes(doc, img["uri"], f"image {image_index}")


@dataclass
class BaseColorTexture:
    """How a material samples its base-colour texture: which SceneData texture, which TEXCOORD set, and
    the KHR_texture_transform (3x3, in glTF's UV space) applied to those coordinates."""

    texture: int
    texcoord: int
    transform: np.ndarray | None


class TextureTable:
    """Base-colour textures of a document: each image decoded once, one Texture per (image, wrap modes)."""

    def __init__(self, doc: Document) -> None:
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


def read_material(doc: Document, index: int, table: TextureTable) -> tuple[Material, BaseColorTexture | None]:
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
            sampling = BaseColorTexture(texture, texcoord, transform)
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


def primitive_uvs(doc: Document, attrs: dict[str, Any], sampling: BaseColorTexture, count: int,
                   what: str) -> np.ndarray:
    """Blender-convention UVs (v up) of a primitive's vertices for its material's base-colour texture;
    zeros when the primitive lacks that TEXCOORD set."""
    key = f"TEXCOORD_{sampling.texcoord}"
    if key not in attrs:
        return np.zeros((count, 2))
    uv = read_accessor(doc, int(attrs[key])).astype(np.float64)
    if uv.shape != (count, 2):
        raise ValueError(f"{what}: {key} must be VEC2 with one entry per vertex, got {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise ValueError(f"{what}: {key} contains NaN or Inf")
    if sampling.transform is not None:
        uv = uv @ sampling.transform[:2, :2].T + sampling.transform[:2, 2]
    return np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)
