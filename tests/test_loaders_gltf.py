"""glTF loader: hand-built files for the accessor corner cases and bad inputs, and round trips through
the real Blender exporter (bpy) for frames, transforms, cameras, lights and materials."""

from __future__ import annotations

import base64
import io
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image
from sim_core.loaders import GLTF_TO_BLENDER, load_gltf
from sim_core.loaders.confined import shown
from sim_core.loaders.gltf import LIGHT_RADIUS_EXTRAS_KEY, LUMENS_PER_WATT

import sim_core

# --------------------------------------------------------------------------------------------------
# A tiny glTF writer for hand-made test files
# --------------------------------------------------------------------------------------------------


class _Builder:
    def __init__(self) -> None:
        self.blob = bytearray()
        self.gltf: dict = {"asset": {"version": "2.0"}, "bufferViews": [], "accessors": [], "meshes": [],
                           "nodes": [], "scenes": [{"nodes": []}], "scene": 0}

    def view(self, data: bytes, stride: int | None = None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        v = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        self.blob.extend(data)
        self.gltf["bufferViews"].append(v)
        return len(self.gltf["bufferViews"]) - 1

    def accessor(self, array: np.ndarray, ctype: int, acc_type: str, **extra: object) -> int:
        view = self.view(np.ascontiguousarray(array).tobytes())
        return self.raw_accessor(view, ctype, acc_type, len(array), **extra)

    def raw_accessor(self, view: int | None, ctype: int, acc_type: str, count: int, **extra: object) -> int:
        acc = {"componentType": ctype, "type": acc_type, "count": count, **extra}
        if view is not None:
            acc["bufferView"] = view
        self.gltf["accessors"].append(acc)
        return len(self.gltf["accessors"]) - 1

    def mesh(self, primitives: list[dict]) -> int:
        self.gltf["meshes"].append({"primitives": primitives})
        return len(self.gltf["meshes"]) - 1

    def node(self, root: bool = True, **fields: object) -> int:
        self.gltf["nodes"].append(dict(fields))
        idx = len(self.gltf["nodes"]) - 1
        if root:
            self.gltf["scenes"][0]["nodes"].append(idx)
        return idx

    def glb(self, path: Path) -> Path:
        gltf = dict(self.gltf)
        gltf["buffers"] = [{"byteLength": len(self.blob)}]
        js = json.dumps(gltf).encode()
        js += b" " * ((4 - len(js) % 4) % 4)
        blob = bytes(self.blob) + b"\0" * ((4 - len(self.blob) % 4) % 4)
        body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942) + blob
        path.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)
        return path

    def gltf_data_uri(self, path: Path) -> Path:
        gltf = dict(self.gltf)
        uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()
        gltf["buffers"] = [{"byteLength": len(self.blob), "uri": uri}]
        path.write_text(json.dumps(gltf))
        return path


TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)  # glTF frame, normal +Z_gltf


def _one_triangle(b: _Builder, positions: np.ndarray = TRI, **node_fields: object) -> None:
    pos = b.accessor(positions, 5126, "VEC3")
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos}}]), **node_fields)


def _to_blender(p: np.ndarray) -> np.ndarray:
    return p @ GLTF_TO_BLENDER[:3, :3].T


def test_frame_conversion_is_x_minus_z_y() -> None:
    assert np.allclose(_to_blender(np.array([1.0, 2.0, 3.0])), [1.0, -3.0, 2.0])


def test_non_indexed_triangle_and_frame(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    sd = load_gltf(b.glb(tmp_path / "t.glb"))
    assert sd.triangles.tolist() == [[0, 1, 2]]
    assert np.allclose(sd.positions, _to_blender(TRI))
    assert sd.object_ids.tolist() == [0] and sd.material_ids.tolist() == [0]
    assert sd.materials[0].name == "default"


@pytest.mark.parametrize("ctype,dtype", [(5121, np.uint8), (5123, np.uint16), (5125, np.uint32)])
def test_index_component_types(tmp_path: Path, ctype: int, dtype: type) -> None:
    b = _Builder()
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
    pos = b.accessor(quad, 5126, "VEC3")
    idx = b.accessor(np.array([0, 1, 2, 0, 2, 3], dtype=dtype), ctype, "SCALAR")
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos}, "indices": idx}]))
    sd = load_gltf(b.glb(tmp_path / "q.glb"))
    assert sd.triangles.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_interleaved_stride_normals_and_quantized_positions(tmp_path: Path) -> None:
    b = _Builder()
    # Interleaved int16 normalized positions (4 bytes padding) + float normals, stride 20.
    q = np.array([[0, 0, 0], [32767, 0, 0], [0, 32767, 0]], dtype=np.int16)
    n = np.tile(np.array([0.0, 0.0, 1.0], dtype=np.float32), (3, 1))
    rec = np.zeros(3, dtype=[("p", "<i2", 3), ("pad", "<i2"), ("n", "<f4", 3)])
    rec["p"], rec["n"] = q, n
    view = b.view(rec.tobytes(), stride=20)
    pos = b.raw_accessor(view, 5122, "VEC3", 3, normalized=True)
    nrm = b.raw_accessor(view, 5126, "VEC3", 3, byteOffset=8)
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos, "NORMAL": nrm}}]), scale=[2.0, 2.0, 2.0])
    sd = load_gltf(b.glb(tmp_path / "i.glb"))
    assert np.allclose(sd.positions, _to_blender(TRI * 2.0), atol=1e-6)
    assert np.allclose(sd.normals, [[0.0, -1.0, 0.0]] * 3)  # +Z_gltf -> -Y_blender


def test_sparse_accessor_overrides_values(tmp_path: Path) -> None:
    b = _Builder()
    base = b.view(np.zeros((3, 3), dtype=np.float32).tobytes())
    sidx = b.view(np.array([1, 2], dtype=np.uint16).tobytes())
    svals = b.view(np.array([[1, 0, 0], [0, 1, 0]], dtype=np.float32).tobytes())
    pos = b.raw_accessor(base, 5126, "VEC3", 3, sparse={
        "count": 2, "indices": {"bufferView": sidx, "componentType": 5123}, "values": {"bufferView": svals}})
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos}}]))
    sd = load_gltf(b.glb(tmp_path / "s.glb"))
    assert np.allclose(sd.positions, _to_blender(TRI))


def test_triangle_strip_keeps_orientation(tmp_path: Path) -> None:
    b = _Builder()
    strip = np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0]], dtype=np.float32)
    b.node(mesh=b.mesh([{"attributes": {"POSITION": b.accessor(strip, 5126, "VEC3")}, "mode": 5}]))
    sd = load_gltf(b.glb(tmp_path / "strip.glb"))
    p = sd.positions.astype(np.float64)
    t = sd.triangles
    normals = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    assert t.shape == (2, 3)
    assert np.all(normals[:, 1] > 0)  # both face -Z_gltf -> +Y_blender, consistently


def test_hierarchy_matrix_and_mirror_flip_winding(tmp_path: Path) -> None:
    b = _Builder()
    pos = b.accessor(TRI, 5126, "VEC3")
    nrm = b.accessor(np.tile(np.array([0, 0, 1], np.float32), (3, 1)), 5126, "VEC3")
    mesh = b.mesh([{"attributes": {"POSITION": pos, "NORMAL": nrm}}])
    child = b.node(root=False, mesh=mesh, scale=[1.0, 1.0, -1.0], name="mirrored")
    mat = np.eye(4)
    mat[:3, 3] = [10.0, 0.0, 0.0]
    b.node(mesh=mesh, matrix=mat.T.reshape(-1).tolist(), children=[child], name="parent")
    sd = load_gltf(b.glb(tmp_path / "h.glb"))
    assert sd.object_names == ["parent", "mirrored"]
    p = sd.positions.astype(np.float64)
    t = sd.triangles
    geo = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    geo /= np.linalg.norm(geo, axis=1, keepdims=True)
    # The mirrored copy's shading normal flips with it (inverse transpose) and its winding follows.
    for tri in range(2):
        assert np.allclose(sd.normals[t[tri]], geo[tri], atol=1e-6)
    assert np.allclose(geo[0], [0, -1, 0]) and np.allclose(geo[1], [0, 1, 0])
    assert np.allclose(p[t[1]], _to_blender(TRI * [1, 1, -1] + [10, 0, 0])[[0, 2, 1]])  # winding flipped


def test_zero_scale_node_gives_degenerate_triangles(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b, name="visible")
    _one_triangle(b, name="hidden", scale=[0.0, 0.0, 0.0], translation=[1.0, 2.0, 3.0])
    sd = load_gltf(b.glb(tmp_path / "z.glb"))
    hidden = sd.positions[sd.triangles[sd.object_ids == 1][0]]
    assert np.allclose(hidden, _to_blender(np.array([1.0, 2.0, 3.0])))  # collapsed onto its origin


def test_gltf_json_with_data_uri(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b, translation=[0.0, 5.0, 0.0])
    sd = load_gltf(b.gltf_data_uri(tmp_path / "t.gltf"))
    assert np.allclose(sd.positions, _to_blender(TRI + np.array([0.0, 5.0, 0.0])))


def test_undecodable_texture(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    b.gltf["images"] = [{"bufferView": b.view(b"not a png at all"), "mimeType": "image/png"}]
    b.gltf["textures"] = [{"source": 0}]
    b.gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    b.gltf["meshes"][0]["primitives"][0]["material"] = 0
    with pytest.raises(ValueError, match="cannot be decoded"):
        load_gltf(b.glb(tmp_path / "tex.glb"))


def _png(rgba: np.ndarray) -> bytes:
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(rgba).save(buf, format="PNG")
    return buf.getvalue()


def _textured_triangle(b: _Builder, uv: np.ndarray, material: dict, image: np.ndarray,
                       sampler: dict | None = None) -> None:
    pos = b.accessor(TRI, 5126, "VEC3")
    tex = b.accessor(uv.astype(np.float32), 5126, "VEC2")
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos, "TEXCOORD_0": tex}, "material": 0}]))
    b.gltf["images"] = [{"bufferView": b.view(_png(image)), "mimeType": "image/png", "name": "img"}]
    b.gltf["textures"] = [{"source": 0, **({"sampler": 0} if sampler is not None else {})}]
    if sampler is not None:
        b.gltf["samplers"] = [sampler]
    b.gltf["materials"] = [material]


def test_base_color_texture_uvs_sampler_and_alpha(tmp_path: Path) -> None:
    image = np.zeros((2, 4, 4), np.uint8)
    image[..., 0] = np.arange(8).reshape(2, 4) * 30
    image[..., 3] = 255
    image[1, 3, 3] = 0  # one transparent texel: the texture can cut the surface out
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])  # glTF UVs: v down from the image's top
    b = _Builder()
    _textured_triangle(b, uv, {"pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                                         "baseColorFactor": [0.5, 1.0, 1.0, 0.8]},
                               "alphaMode": "MASK", "alphaCutoff": 0.3},
                       image, sampler={"wrapS": 33071, "wrapT": 33648})
    sd = load_gltf(b.glb(tmp_path / "tex.glb"))
    (t,) = sd.textures
    assert np.array_equal(t.image, image) and t.colorspace == "srgb"
    assert (t.wrap_u, t.wrap_v) == ("clamp", "mirror")
    (m,) = sd.materials
    assert m.base_color_texture == 0 and m.base_color == (0.5, 1.0, 1.0)
    assert (m.alpha, m.alpha_mode, m.alpha_cutoff) == (pytest.approx(0.8), "clip", pytest.approx(0.3))
    # Blender's convention: v up, so glTF's (u, v) becomes (u, 1 - v).
    assert np.allclose(sd.uvs, [[0.0, 1.0], [1.0, 1.0], [0.0, 0.0]])
    scene = sim_core.Scene.from_scene_data(sd)
    assert {"textures", "alpha_cutouts"} <= set(scene.stats["effects"])


def test_texture_transform_and_blend_mode(tmp_path: Path) -> None:
    image = np.full((4, 4, 3), 200, np.uint8)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    transform = {"offset": [0.25, 0.5], "rotation": math.pi / 2, "scale": [2.0, 3.0]}
    b = _Builder()
    _textured_triangle(b, uv, {"pbrMetallicRoughness": {"baseColorTexture": {
        "index": 0, "extensions": {"KHR_texture_transform": transform}}}, "alphaMode": "BLEND"}, image)
    sd = load_gltf(b.glb(tmp_path / "tex.glb"))
    # KHR_texture_transform: uv' = T R S uv with R = [[cos, sin], [-sin, cos]] (the extension's matrix).
    c, s_ = math.cos(math.pi / 2), math.sin(math.pi / 2)
    rs = np.array([[c, s_], [-s_, c]]) @ np.diag([2.0, 3.0])
    expected = uv @ rs.T + [0.25, 0.5]
    assert np.allclose(sd.uvs, np.stack([expected[:, 0], 1.0 - expected[:, 1]], axis=1), atol=1e-6)
    (m,) = sd.materials
    assert m.alpha_mode == "hashed" and sd.textures[0].wrap_u == "repeat"
    # An opaque texture with alpha 1 can never cut anything out: no alpha tests are modelled.
    assert "alpha_cutouts" not in sim_core.Scene.from_scene_data(sd).stats["effects"]


def test_untextured_scene_has_no_uvs(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    sd = load_gltf(b.glb(tmp_path / "t.glb"))
    assert sd.uvs is None and sd.textures == []


def test_spot_blend_comes_back_from_the_inner_cone(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    cone = {"outerConeAngle": 0.6, "innerConeAngle": 0.6 * 0.75}  # Blender: inner = outer * (1 - blend)
    b.gltf["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "spot", "intensity": 1000.0,
                                                                 "spot": cone}]}}
    b.node(extensions={"KHR_lights_punctual": {"light": 0}})
    (light,) = load_gltf(b.glb(tmp_path / "spot.glb")).lights
    assert light.spot_angle == pytest.approx(0.6) and light.spot_blend == pytest.approx(0.25)
    assert light.intensity == pytest.approx(1000.0 / LUMENS_PER_WATT)


def test_environment_extras_exr(tmp_path: Path) -> None:
    import OpenEXR

    sky = np.random.default_rng(0).random((8, 16, 3)).astype(np.float32)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"RGB": sky}) as f:
        f.write(str(tmp_path / "sky.exr"))
    b = _Builder()
    _one_triangle(b)
    b.gltf["scenes"][0]["extras"] = {"render_budget_environment": "sky.exr"}
    sd = load_gltf(b.glb(tmp_path / "env.glb"))
    assert isinstance(sd.environment, np.ndarray) and np.array_equal(sd.environment, sky)
    b.gltf["scenes"][0]["extras"] = {"render_budget_environment": "missing.exr"}
    with pytest.raises(FileNotFoundError, match=r"missing\.exr"):
        load_gltf(b.glb(tmp_path / "env2.glb"))


# ----------------------------------- files outside the document ------------------------------------


def _external_buffer(b: _Builder, path: Path, uri: str) -> Path:
    """A .gltf whose only buffer is the file ``uri`` (written next to it as ``geometry.bin``)."""
    (path.parent / "geometry.bin").write_bytes(bytes(b.blob))
    gltf = dict(b.gltf)
    gltf["buffers"] = [{"byteLength": len(b.blob), "uri": uri}]
    path.write_text(json.dumps(gltf))
    return path


def _scene_folder_beside_a_secret(tmp_path: Path) -> tuple[_Builder, Path, Path]:
    """A one-triangle document, a file outside the scene's folder holding its geometry, and the folder."""
    b = _Builder()
    _one_triangle(b)
    secret = tmp_path / "secret.bin"
    secret.write_bytes(bytes(b.blob))
    scene_dir = tmp_path / "scene"
    scene_dir.mkdir()
    return b, secret, scene_dir


def test_external_buffer_in_the_scene_folder(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "geometry.bin").write_bytes(bytes(b.blob))
    sd = load_gltf(_external_buffer(b, tmp_path / "t.gltf", "geometry.bin"))
    assert np.allclose(sd.positions, _to_blender(TRI))
    assert load_gltf(_external_buffer(b, tmp_path / "u.gltf", "sub/geometry.bin")).positions.shape == (3, 3)
    assert load_gltf(_external_buffer(b, tmp_path / "v.gltf", "sub%2Fgeometry.bin")).positions.shape == (3, 3)


@pytest.mark.parametrize("uri", ["../secret.bin", "%2e%2e/secret.bin", "%2E%2E%2Fsecret.bin",
                                 "sub/../../secret.bin", "SECRET_ABSOLUTE", "link.bin"])
def test_external_files_stay_inside_the_scene_folder(tmp_path: Path, uri: str,
                                                     opened_files: list[str]) -> None:
    """Relative references are resolved (``..``, percent-encoding, symbolic links) and must stay in the
    scene's folder; the message names the reference, not where it leads, and nothing outside is read."""
    b, secret, scene_dir = _scene_folder_beside_a_secret(tmp_path)
    (scene_dir / "link.bin").symlink_to(secret)
    uri = uri.replace("SECRET_ABSOLUTE", str(secret))
    path = _external_buffer(b, scene_dir / "t.gltf", uri)
    opened_files.clear()
    with pytest.raises(ValueError, match="outside the scene's folder") as info:
        load_gltf(path)
    assert str(secret) not in str(info.value).replace(uri, "")
    assert str(secret.resolve()) not in opened_files


@pytest.mark.parametrize("uri", ["file:///etc/passwd", "http://example.com/x.bin", "C:/x.bin"])
def test_urls_are_not_files(tmp_path: Path, uri: str) -> None:
    b = _Builder()
    _one_triangle(b)
    with pytest.raises(ValueError, match="not a relative file reference"):
        load_gltf(_external_buffer(b, tmp_path / "t.gltf", uri))


def test_missing_external_buffer_names_the_reference_only(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    with pytest.raises(FileNotFoundError, match=r"'nope\.bin' not found") as info:
        load_gltf(_external_buffer(b, tmp_path / "t.gltf", "nope.bin"))
    assert str(tmp_path / "nope.bin") not in str(info.value)


@pytest.mark.parametrize("what", ["buffer", "image", "environment"])
@pytest.mark.parametrize("reference", ["geometry.bin", "ABSOLUTE", "../secret.bin", "%2e%2e/secret.bin"])
def test_self_contained_refuses_every_external_reference_before_reading(
        tmp_path: Path, what: str, reference: str, opened_files: list[str]) -> None:
    """Uploads (``self_contained=True``): only the binary chunk and data: URIs. Any other reference, be
    it next to the file or not, is refused before any file but the scene itself is opened."""
    b, outside, scene_dir = _scene_folder_beside_a_secret(tmp_path)
    (scene_dir / "geometry.bin").write_bytes(bytes(b.blob))
    reference = reference.replace("ABSOLUTE", str(outside))
    if what == "buffer":
        path = _external_buffer(b, scene_dir / "t.gltf", reference)
        (scene_dir / "geometry.bin").write_bytes(bytes(b.blob))
    elif what == "image":
        b.gltf["images"] = [{"uri": reference}]
        b.gltf["textures"] = [{"source": 0}]
        b.gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
        b.gltf["meshes"][0]["primitives"][0]["material"] = 0
        path = b.glb(scene_dir / "t.glb")
    else:
        b.gltf["scenes"][0]["extras"] = {"render_budget_environment": reference}
        path = b.glb(scene_dir / "t.glb")
    opened_files.clear()
    with pytest.raises(ValueError, match="self-contained") as info:
        load_gltf(path, self_contained=True)
    assert opened_files == [str(path.resolve())]
    # the reference as the message shows it (cut at 80 characters: a long temporary folder is cut)
    assert str(tmp_path) not in str(info.value).replace(shown(reference), "").replace(str(path), "")


def test_self_contained_accepts_the_binary_chunk_and_data_uris(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    png = io.BytesIO()
    Image.new("RGB", (2, 2), (255, 0, 0)).save(png, format="PNG")
    b.gltf["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(png.getvalue()).decode()}]
    b.gltf["textures"] = [{"source": 0}]
    b.gltf["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    b.gltf["meshes"][0]["primitives"][0]["material"] = 0
    assert load_gltf(b.glb(tmp_path / "t.glb"), self_contained=True).materials[0].base_color[0] > 0.99
    sd = load_gltf(b.gltf_data_uri(tmp_path / "t.gltf"), self_contained=True)
    assert np.allclose(sd.positions, _to_blender(TRI))


# ----------------------------------- bad inputs ----------------------------------------------------


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        load_gltf(tmp_path / "nope.glb")


def test_not_gltf(tmp_path: Path) -> None:
    (tmp_path / "x.glb").write_bytes(b"\x00\x01binary garbage")
    with pytest.raises(ValueError, match="not a glTF"):
        load_gltf(tmp_path / "x.glb")
    (tmp_path / "y.gltf").write_text('{"meshes": []}')
    with pytest.raises(ValueError, match="no 'asset'"):
        load_gltf(tmp_path / "y.gltf")


def test_truncated_glb(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    data = b.glb(tmp_path / "t.glb").read_bytes()
    (tmp_path / "cut.glb").write_bytes(data[:-20])
    with pytest.raises(ValueError, match="truncated"):
        load_gltf(tmp_path / "cut.glb")


def test_buffer_view_past_end(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    b.gltf["accessors"][0]["count"] = 30
    with pytest.raises(ValueError, match="truncated"):
        load_gltf(b.glb(tmp_path / "t.glb"))


def test_nan_position(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b, positions=np.array([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0]], dtype=np.float32))
    with pytest.raises(ValueError, match="NaN or Inf"):
        load_gltf(b.glb(tmp_path / "nan.glb"))


def test_inf_position(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b, positions=np.array([[0, 0, 0], [np.inf, 0, 0], [0, 1, 0]], dtype=np.float32))
    with pytest.raises(ValueError, match="NaN or Inf"):
        load_gltf(b.glb(tmp_path / "inf.glb"))


def test_index_out_of_range(tmp_path: Path) -> None:
    b = _Builder()
    pos = b.accessor(TRI, 5126, "VEC3")
    idx = b.accessor(np.array([0, 1, 3], dtype=np.uint16), 5123, "SCALAR")
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos}, "indices": idx}]))
    with pytest.raises(ValueError, match="out of range"):
        load_gltf(b.glb(tmp_path / "oor.glb"))


def test_empty_scene(tmp_path: Path) -> None:
    b = _Builder()
    b.node(name="just an empty")
    with pytest.raises(ValueError, match="no triangles"):
        load_gltf(b.glb(tmp_path / "empty.glb"))


def test_node_cycle(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    b.gltf["nodes"][0]["children"] = [0]
    with pytest.raises(ValueError, match="twice"):
        load_gltf(b.glb(tmp_path / "cycle.glb"))


def test_unsupported_required_extension(tmp_path: Path) -> None:
    b = _Builder()
    _one_triangle(b)
    b.gltf["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    with pytest.raises(ValueError, match="KHR_draco_mesh_compression"):
        load_gltf(b.glb(tmp_path / "draco.glb"))


def _valid_glb(tmp_path: Path) -> bytes:
    b = _Builder()
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
    pos = b.accessor(quad, 5126, "VEC3")
    nrm = b.accessor(np.tile(np.array([0, 0, 1], np.float32), (4, 1)), 5126, "VEC3")
    idx = b.accessor(np.array([0, 1, 2, 0, 2, 3], dtype=np.uint16), 5123, "SCALAR")
    b.gltf["materials"] = [{"pbrMetallicRoughness": {"metallicFactor": 0.5}}]
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos, "NORMAL": nrm}, "indices": idx, "material": 0}]),
           rotation=[0.0, 0.0, 0.3826834, 0.9238795])
    return b.glb(tmp_path / "valid.glb").read_bytes()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_corrupted_files_raise_value_errors_only(tmp_path: Path, data: st.DataObject) -> None:
    """Uploads are untrusted: flipped bytes, truncation and JSON of the wrong shape give a SceneData or a
    ValueError, never another exception, a crash or a hang."""
    blob = bytearray(_valid_glb(tmp_path))
    kind = data.draw(st.sampled_from(["bytes", "truncate", "json"]))
    if kind == "bytes":
        for _ in range(data.draw(st.integers(1, 8))):
            blob[data.draw(st.integers(0, len(blob) - 1))] = data.draw(st.integers(0, 255))
    elif kind == "truncate":
        blob = blob[: data.draw(st.integers(0, len(blob) - 1))]
    else:
        n = struct.unpack_from("<I", blob, 12)[0]
        doc = json.loads(blob[20 : 20 + n])
        section = data.draw(st.sampled_from(["accessors", "bufferViews", "nodes", "meshes", "materials"]))
        items = doc[section]
        key = data.draw(st.sampled_from(sorted(items[0]))) if items[0] else None
        junk = data.draw(st.one_of(st.none(), st.integers(-(2**40), 2**40), st.floats(allow_nan=True),
                                   st.text(max_size=3), st.lists(st.integers(-3, 3), max_size=5),
                                   st.dictionaries(st.text(max_size=2), st.integers(), max_size=2)))
        if key is not None:
            items[0][key] = junk
        js = json.dumps(doc).encode()
        js += b" " * ((4 - len(js) % 4) % 4)
        rest = blob[20 + n :]
        body = struct.pack("<II", len(js), 0x4E4F534A) + js + bytes(rest)
        blob = bytearray(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)
    path = tmp_path / "fuzz.glb"
    path.write_bytes(bytes(blob))
    try:
        sd = load_gltf(path)
    except ValueError:
        return
    assert sd.triangles.ndim == 2 and sd.triangles.shape[1] == 3
    assert np.all(np.isfinite(sd.positions))
    assert sd.triangles.max() < sd.positions.shape[0]


# --------------------------------------------------------------------------------------------------
# Round trips through Blender's own exporter
# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bpy_mod():
    bpy = pytest.importorskip("bpy")
    return bpy


def _reset(bpy) -> None:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def _export(bpy, path: Path) -> Path:
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", export_apply=True, export_lights=True,
                              export_cameras=True, export_yup=True, export_extras=True)
    return path


def _blender_triangles(bpy, obj) -> np.ndarray:
    """World-frame triangles (T, 3, 3) of an object's evaluated mesh, as Blender itself has them."""
    deps = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(deps)
    mesh = ev.to_mesh()
    mesh.calc_loop_triangles()
    tris = np.zeros(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    co = np.zeros(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    m = np.array(obj.matrix_world)
    world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return world[tris.reshape(-1, 3)]


def _matched(mine: np.ndarray, theirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pair triangles by centroid (file order differs from Blender's); returns both unit normals, paired,
    so a test can check winding (orientation) as well as position."""

    def normals(t: np.ndarray) -> np.ndarray:
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    ca, cb = mine.mean(axis=1), theirs.mean(axis=1)
    dist = np.linalg.norm(ca[:, None, :] - cb[None, :, :], axis=2)
    j = dist.argmin(axis=1)
    assert np.all(dist[np.arange(len(j)), j] < 1e-4), "a triangle has no counterpart in Blender's mesh"
    assert np.unique(j).size == len(j), "triangles matched twice"
    return normals(mine), normals(theirs)[j]


@pytest.mark.blender
def test_blender_meshes_transforms_and_mirror(bpy_mod, tmp_path: Path) -> None:
    bpy = bpy_mod
    _reset(bpy)
    bpy.ops.object.empty_add(location=(1.0, -2.0, 0.5), rotation=(0.3, -0.4, 1.1))
    parent = bpy.context.active_object
    parent.scale = (1.5, 0.7, 1.2)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.5, 0.25, 2.0), rotation=(0.2, 0.1, -0.6))
    cube = bpy.context.active_object
    cube.name = "Box"
    cube.parent = parent
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, location=(-3.0, 1.0, 1.0))
    sphere = bpy.context.active_object
    sphere.name = "Mirrored"
    sphere.scale = (1.0, -2.0, 0.5)  # negative determinant: the exporter keeps it, winding must flip
    sphere.modifiers.new("sub", "SUBSURF").levels = 1
    bpy.ops.mesh.primitive_plane_add(size=10.0, location=(0, 0, -1))
    bpy.context.active_object.name = "Floor"
    sd = load_gltf(_export(bpy, tmp_path / "m.glb"))

    assert sorted(sd.object_names) == ["Box", "Floor", "Mirrored"]
    for name in sd.object_names:
        obj = bpy.data.objects[name]
        mine = sd.positions.astype(np.float64)[sd.triangles[sd.object_ids == sd.object_names.index(name)]]
        theirs = _blender_triangles(bpy, obj)
        assert mine.shape == theirs.shape, name
        na, nb = _matched(mine, theirs)
        # Blender keeps a mirrored object's loop order and flips its face normals when it evaluates them,
        # so the front face there is the raw world winding times the sign of the determinant.
        nb = nb * np.sign(np.linalg.det(np.array(obj.matrix_world)[:3, :3]))
        assert np.all(np.sum(na * nb, axis=1) > 0.999), f"{name}: winding or frame differs"
    # Shading normals went through the inverse transpose: on the flat cube they equal the face normals.
    box = sd.object_names.index("Box")
    t = sd.triangles[sd.object_ids == box]
    p = sd.positions.astype(np.float64)
    geo = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    geo /= np.linalg.norm(geo, axis=1, keepdims=True)
    for k in range(3):
        assert np.all(np.sum(sd.normals[t[:, k]] * geo, axis=1) > 0.9999)
    # Smooth mirrored sphere: normals point outwards from its centre after the flip.
    mirrored = sd.object_names.index("Mirrored")
    t = sd.triangles[sd.object_ids == mirrored]
    verts = np.unique(t)
    outward = p[verts] - np.array([-3.0, 1.0, 1.0])
    assert np.all(np.sum(sd.normals[verts] * outward, axis=1) > 0)


@pytest.mark.blender
def test_blender_gpu_instancing(bpy_mod, tmp_path: Path) -> None:
    """Linked duplicates under an empty, exported with EXT_mesh_gpu_instancing: one object per instance,
    placed where Blender has them."""
    bpy = bpy_mod
    _reset(bpy)
    bpy.ops.object.empty_add(location=(1.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.4))
    empty = bpy.context.active_object
    bpy.ops.mesh.primitive_cone_add(vertices=8)
    cones = [bpy.context.active_object]
    for k in range(4):
        obj = bpy.data.objects.new(f"Cone{k}", cones[0].data)
        bpy.context.scene.collection.objects.link(obj)
        obj.location, obj.rotation_euler = (2.0 * k, 1.0, 0.5 * k), (0.3 * k, 0.0, 0.2)
        obj.scale = (1.0, 1.0, 1.0 + k / 5)
        cones.append(obj)
    for obj in cones:
        obj.parent = empty
    path = tmp_path / "gpu.glb"
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", export_apply=True,
                              export_gpu_instances=True)
    raw = json.loads(path.read_bytes()[20 : 20 + struct.unpack_from("<I", path.read_bytes(), 12)[0]])
    assert "EXT_mesh_gpu_instancing" in raw.get("extensionsUsed", [])
    sd = load_gltf(path)
    assert len(sd.object_names) == len(cones)
    theirs = np.concatenate([_blender_triangles(bpy, obj) for obj in cones])
    mine = sd.positions.astype(np.float64)[sd.triangles]
    assert mine.shape == theirs.shape
    na, nb = _matched(mine, theirs)
    assert np.all(np.sum(na * nb, axis=1) > 0.999)


@pytest.mark.blender
@pytest.mark.parametrize("res,fit", [((1920, 1080), "AUTO"), ((600, 900), "AUTO"), ((1280, 720), "VERTICAL")])
def test_blender_camera(bpy_mod, tmp_path: Path, res: tuple[int, int], fit: str) -> None:
    bpy = bpy_mod
    _reset(bpy)
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.object.empty_add(location=(2.0, 0.0, 1.0), rotation=(0.0, 0.0, 0.7))
    rig = bpy.context.active_object
    bpy.ops.object.camera_add(location=(6.0, -5.0, 3.0), rotation=(1.1, 0.05, 0.9))
    cam = bpy.context.active_object
    cam.parent = rig
    cam.data.lens = 35.0
    cam.data.sensor_fit = fit
    scene = bpy.context.scene
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = res
    sd = load_gltf(_export(bpy, tmp_path / "c.glb"))
    assert len(sd.cameras) == 1
    got = sd.cameras[0]
    assert np.allclose(got.matrix_world, np.array(cam.matrix_world), atol=1e-5)
    w, h = res
    # Blender's angle spans the sensor-fit axis (AUTO: the larger image side).
    horizontal = fit == "HORIZONTAL" or (fit == "AUTO" and w >= h)
    expected = 2 * math.atan(math.tan(cam.data.angle / 2) * h / w) if horizontal else cam.data.angle
    assert got.vfov == pytest.approx(expected, rel=1e-5)
    assert got.aspect == pytest.approx(w / h, rel=1e-6)
    # Looks down local -Z in the Blender frame: the camera's forward is where Blender says it is.
    fwd = got.matrix_world[:3, :3] @ [0, 0, -1]
    assert np.allclose(fwd, -np.array(cam.matrix_world.to_3x3().col[2]), atol=1e-5)


@pytest.mark.blender
def test_blender_lights_radiometric_units(bpy_mod, tmp_path: Path) -> None:
    bpy = bpy_mod
    _reset(bpy)
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.object.light_add(type="POINT", location=(1.0, 2.0, 5.0))
    point = bpy.context.active_object
    point.data.energy = 1000.0
    point.data.color = (1.0, 0.5, 0.25)
    point.data[LIGHT_RADIUS_EXTRAS_KEY] = 0.25  # exported as light extras (glTF has no light size)
    bpy.ops.object.light_add(type="SPOT", location=(-2.0, 0.0, 4.0), rotation=(0.4, 0.0, 0.3))
    spot = bpy.context.active_object
    spot.data.energy = 250.0
    spot.data.spot_size = math.radians(50.0)
    bpy.ops.object.light_add(type="SUN", rotation=(0.6, 0.2, 0.0))
    sun = bpy.context.active_object
    sun.data.energy = 3.5
    path = _export(bpy, tmp_path / "l.glb")
    sd = load_gltf(path)
    lights = {light.name: light for light in sd.lights}
    assert set(lights) == {point.data.name, spot.data.name, sun.data.name}

    # What Blender wrote ('SPEC' mode: W/(4 pi) * 683 cd) is what we undo.
    raw = json.loads(path.read_bytes()[20 : 20 + struct.unpack_from("<I", path.read_bytes(), 12)[0]])
    written = {lt["name"]: lt["intensity"] for lt in raw["extensions"]["KHR_lights_punctual"]["lights"]}
    assert written[point.data.name] == pytest.approx(1000.0 / (4 * math.pi) * 683.0, rel=1e-6)
    assert lights[point.data.name].intensity == pytest.approx(written[point.data.name] / LUMENS_PER_WATT)

    p = lights[point.data.name]
    assert p.kind == "point" and p.intensity == pytest.approx(1000.0 / (4 * math.pi), rel=1e-6)
    assert np.allclose(p.position, [1.0, 2.0, 5.0], atol=1e-6)
    assert np.allclose(p.color, [1.0, 0.5, 0.25])
    assert p.radius == pytest.approx(0.25)
    s = lights[spot.data.name]
    assert s.kind == "spot" and s.intensity == pytest.approx(250.0 / (4 * math.pi), rel=1e-6)
    assert s.spot_angle == pytest.approx(math.radians(25.0), rel=1e-5)
    assert np.allclose(s.position, [-2.0, 0.0, 4.0], atol=1e-6)
    assert np.allclose(s.direction, -np.array(spot.matrix_world.to_3x3().col[2]), atol=1e-5)
    d = lights[sun.data.name]
    assert d.kind == "sun" and d.intensity == pytest.approx(3.5, rel=1e-6) and d.radius == 0.0
    assert np.allclose(d.direction, -np.array(sun.matrix_world.to_3x3().col[2]), atol=1e-5)


@pytest.mark.blender
def test_blender_principled_materials(bpy_mod, tmp_path: Path) -> None:
    bpy = bpy_mod
    _reset(bpy)
    specs = {
        "Glass": {"Base Color": (0.9, 0.95, 1.0, 1.0), "Roughness": 0.05, "Transmission Weight": 1.0,
                  "IOR": 1.45, "Metallic": 0.0},
        "Chrome": {"Base Color": (0.8, 0.8, 0.8, 1.0), "Metallic": 1.0, "Roughness": 0.1},
        "Lamp": {"Base Color": (0.1, 0.1, 0.1, 1.0), "Emission Color": (1.0, 0.8, 0.5, 1.0),
                 "Emission Strength": 4.0, "Roughness": 0.7},
    }
    for i, (name, inputs) in enumerate(specs.items()):
        bpy.ops.mesh.primitive_cube_add(location=(3.0 * i, 0.0, 0.0))
        mat = bpy.data.materials.new(name)
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        for key, value in inputs.items():
            bsdf.inputs[key].default_value = value
        bpy.context.active_object.data.materials.append(mat)
    bpy.context.scene["render_budget_environment"] = [0.05, 0.1, 0.2]
    sd = load_gltf(_export(bpy, tmp_path / "mat.glb"))
    mats = {m.name: m for m in sd.materials}
    assert mats["Glass"].transmission == pytest.approx(1.0)
    assert mats["Glass"].ior == pytest.approx(1.45, rel=1e-5)
    assert mats["Glass"].roughness == pytest.approx(0.05, rel=1e-5)
    assert mats["Chrome"].metallic == pytest.approx(1.0) and mats["Chrome"].transmission == 0.0
    assert mats["Chrome"].roughness == pytest.approx(0.1, rel=1e-5)
    assert np.allclose(mats["Lamp"].emission, [4.0, 3.2, 2.0], rtol=1e-5)
    assert np.allclose(mats["Lamp"].base_color, [0.1, 0.1, 0.1], rtol=1e-5)
    # Each cube carries its own material on all its triangles.
    for oid, name in enumerate(sd.object_names):
        used = {sd.materials[i].name for i in np.unique(sd.material_ids[sd.object_ids == oid])}
        assert used == {bpy.data.objects[name].data.materials[0].name}
    assert sd.environment == pytest.approx((0.05, 0.1, 0.2))


def _corner_case_files(tmp_path: Path) -> dict[str, Path]:
    """Hand-built files exercising what Blender's exporter never writes: strides, quantised positions,
    sparse accessors, strips, fans, matrices and a mirrored child."""
    files = {}
    b = _Builder()
    q = np.array([[0, 0, 0], [32767, 0, 0], [0, 32767, 0], [32767, 32767, 16000]], dtype=np.int16)
    rec = np.zeros(4, dtype=[("p", "<i2", 3), ("pad", "<i2"), ("n", "<f4", 3)])
    rec["p"], rec["n"] = q, (0.0, 0.0, 1.0)
    view = b.view(rec.tobytes(), stride=20)
    pos = b.raw_accessor(view, 5122, "VEC3", 4, normalized=True)
    idx = b.accessor(np.array([0, 1, 2, 2, 1, 3], dtype=np.uint8), 5121, "SCALAR")
    b.node(mesh=b.mesh([{"attributes": {"POSITION": pos}, "indices": idx}]), scale=[2.0, 1.0, 3.0],
           rotation=[0.2, 0.3, 0.1, 0.927], translation=[1.0, 2.0, -1.0])
    files["quantised"] = b.glb(tmp_path / "quantised.glb")

    b = _Builder()
    base = b.view(np.tile(np.array([0.5, 0.5, 0.0], np.float32), (5, 1)).tobytes())
    sidx = b.view(np.array([0, 1, 3, 4], dtype=np.uint32).tobytes())
    svals = b.view(np.array([[0, 0, 0], [2, 0, 0], [2, 1, 1], [0, 1, 0]], dtype=np.float32).tobytes())
    pos = b.raw_accessor(base, 5126, "VEC3", 5, sparse={
        "count": 4, "indices": {"bufferView": sidx, "componentType": 5125}, "values": {"bufferView": svals}})
    fan = b.mesh([{"attributes": {"POSITION": pos}, "mode": 6}])
    strip_pos = b.accessor(np.array([[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 1], [2, 0, 0]], np.float32),
                           5126, "VEC3")
    strip = b.mesh([{"attributes": {"POSITION": strip_pos}, "mode": 5}])
    child = b.node(root=False, mesh=strip, scale=[1.0, -1.0, 1.0], translation=[0.0, 0.0, 2.0])
    m = np.eye(4)
    m[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    m[:3, 3] = [3.0, 0.0, 1.0]
    b.node(mesh=fan, matrix=m.T.reshape(-1).tolist(), children=[child])
    files["sparse_fan_strip"] = b.glb(tmp_path / "sparse_fan_strip.glb")
    return files


@pytest.mark.blender
def test_corner_cases_match_blenders_gltf_importer(bpy_mod, tmp_path: Path) -> None:
    """Blender's own glTF importer is an independent decoder: same world triangles, same winding."""
    bpy = bpy_mod
    for name, path in _corner_case_files(tmp_path).items():
        _reset(bpy)
        bpy.ops.import_scene.gltf(filepath=str(path))  # converts Y-up to Z-up like the loader
        objs = [o for o in bpy.context.scene.objects if o.type == "MESH"]
        per_object = [_blender_triangles(bpy, o) for o in objs]
        theirs = np.concatenate(per_object)
        signs = np.concatenate([np.full(len(t), np.sign(np.linalg.det(np.array(o.matrix_world)[:3, :3])))
                                for t, o in zip(per_object, objs, strict=True)])
        sd = load_gltf(path)
        mine = sd.positions.astype(np.float64)[sd.triangles]
        assert mine.shape == theirs.shape, name
        area = np.linalg.norm(np.cross(theirs[:, 1] - theirs[:, 0], theirs[:, 2] - theirs[:, 0]), axis=1)
        keep = area > 1e-9  # compare the non-degenerate ones
        na, nb = _matched(mine[keep], theirs[keep])
        assert np.all(np.sum(na * nb * signs[keep][:, None], axis=1) > 0.999), name


@pytest.mark.blender
def test_blender_base_color_texture_travels_with_its_uvs(bpy_mod, tmp_path: Path) -> None:
    """A Blender image texture comes back as the same image (row 0 at the top, sRGB bytes) and the mesh's
    own UVs (Blender's convention, v up), so the simulator samples what Cycles samples."""
    bpy = bpy_mod
    _reset(bpy)
    bpy.ops.mesh.primitive_cube_add()
    cube = bpy.context.active_object
    mat = bpy.data.materials.new("Textured")
    tree = mat.node_tree
    img = bpy.data.images.new("halves", 8, 8)  # sRGB byte image: top half red, bottom half half-blue
    px = np.zeros((8, 8, 4), np.float32)  # Blender's rows run bottom to top
    px[..., 3] = 1.0
    px[4:, :, 0] = 1.0
    px[:4, :, 2] = 0.5
    img.pixels.foreach_set(px.reshape(-1))
    img.pack()
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.extension = "EXTEND"
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    cube.data.materials.append(mat)
    sd = load_gltf(_export(bpy, tmp_path / "tex.glb"))
    (m,) = [m for m in sd.materials if m.name == "Textured"]
    assert m.base_color == (1.0, 1.0, 1.0) and m.base_color_texture == 0
    (t,) = sd.textures
    assert t.image.dtype == np.uint8 and t.image.shape[:2] == (8, 8) and t.colorspace == "srgb"
    assert t.wrap_u == t.wrap_v == "clamp"
    assert np.all(t.image[:4, :, :3] == [255, 0, 0]) and np.all(t.image[4:, :, :3] == [0, 0, 128])
    # Every loaded vertex (position, UV) is one of the cube's loops in Blender (positions: Z up).
    mesh = cube.data
    loops = {(tuple(np.round(np.array(mesh.vertices[lp.vertex_index].co), 4)),
              tuple(np.round(np.array(mesh.uv_layers.active.data[lp.index].uv), 4))) for lp in mesh.loops}
    mine = {(tuple(np.round(p, 4)), tuple(np.round(uv, 4)))
            for p, uv in zip(sd.positions, sd.uvs, strict=True)}
    assert mine == loops
