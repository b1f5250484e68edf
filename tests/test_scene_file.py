"""The render-budget scene file: round trips (same scene, same bytes, same id), the simulator renders what
was written, and malformed files get a ValueError naming the problem."""

from __future__ import annotations

import hashlib
import io
import json
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sim_core.loaders import is_scene_file, load_scene_file, read_scene_file, write_scene_file
from sim_core.loaders.scene_file import MANIFEST, Limits, scene_file_bytes
from sim_core.scene_data import CameraData, Light, Material, SceneData, Texture

import sim_core


def sample_scene(env: object = "map") -> SceneData:
    pos = np.array([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]],
                   np.float32)
    tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]], np.uint32)
    nrm = np.tile([0, 0, 1], (7, 1)).astype(np.float32)
    if env == "map":
        environment = np.linspace(0, 2, 4 * 8 * 3, dtype=np.float32).reshape(4, 8, 3)
    else:
        environment = env
    cam = np.eye(4)
    cam[:3, 3] = [0, -8, 4]
    checker = np.zeros((8, 8, 4), np.uint8)
    checker[::2, ::2] = 255
    checker[..., 3] = 200
    return SceneData(
        positions=pos, triangles=tri, normals=nrm,
        uvs=np.linspace(0, 1, 14, dtype=np.float32).reshape(7, 2),
        textures=[Texture(checker, colorspace="srgb", wrap_u="mirror", name="checker"),
                  Texture(np.full((2, 2, 3), 0.25, np.float32), colorspace="linear", wrap_v="clamp")],
        material_ids=np.array([0, 0, 1], np.uint32), object_ids=np.array([0, 0, 1], np.uint32),
        materials=[Material(base_color=(0.5, 0.4, 0.3), roughness=0.45, metallic=1.0, name="floor",
                            base_color_texture=0, alpha_mode="hashed"),
                   Material(transmission=1.0, ior=1.45, emission=(0.1, 0.0, 0.0), name="glass", alpha=0.5,
                            alpha_mode="clip", base_color_texture=1)],
        lights=[Light(kind="point", position=(1, 2, 3), intensity=80.0, radius=0.1, name="key"),
                Light(kind="sun", direction=(0.3, 0.2, -1.0), intensity=3.0, radius=0.01, name="sun"),
                Light(kind="area", direction=(0, 0, -1), tangent=(1, 1, 0), shape="ellipse", size=2.0,
                      size_y=0.5, intensity=12.0, name="soft"),
                Light(kind="spot", spot_angle=0.4, spot_blend=0.6, intensity=30.0, name="spot")],
        cameras=[CameraData(matrix_world=cam, vfov=0.6, aspect=16 / 9, name="Camera")],
        environment=environment, environment_strength=1.5, environment_rotation=-0.7,
        object_names=["Floor", "Tri"],
    )


NOTES = [{"severity": "warning", "subject": "material 'x'", "message": "approximated"}]


def test_round_trip_same_bytes_same_id(tmp_path: Path):
    data = sample_scene()
    a, b = tmp_path / "a.rbscene", tmp_path / "b.rbscene"
    id_a = write_scene_file(a, data, NOTES)
    content = read_scene_file(a)
    id_b = write_scene_file(b, content.data, content.notes)
    assert id_a == id_b == hashlib.sha256(a.read_bytes()).hexdigest()
    assert a.read_bytes() == b.read_bytes()
    assert content.notes == NOTES and content.version == 1
    got = content.data
    for attr in ("positions", "triangles", "normals", "uvs", "material_ids", "object_ids", "environment"):
        assert np.array_equal(getattr(got, attr), getattr(data, attr)), attr
    assert (got.environment_strength, got.environment_rotation) == (1.5, -0.7)
    for a_tex, b_tex in zip(got.textures, data.textures, strict=True):
        assert np.array_equal(a_tex.image, b_tex.image) and a_tex.image.dtype == b_tex.image.dtype
        assert (a_tex.colorspace, a_tex.wrap_u, a_tex.wrap_v, a_tex.name) == \
            (b_tex.colorspace, b_tex.wrap_u, b_tex.wrap_v, b_tex.name)
    assert got.materials == data.materials and got.lights == data.lights
    assert got.object_names == data.object_names
    assert np.array_equal(got.cameras[0].matrix_world, data.cameras[0].matrix_world)
    assert got.cameras[0].vfov == 0.6 and got.source == str(a)
    # the native scene built from the file is the one built from the data
    assert sim_core.Scene.from_scene_file(a).content_hash == sim_core.Scene.from_scene_data(data).content_hash


def test_environment_kinds_and_half_floats(tmp_path: Path):
    for env in (None, (0.1, 0.2, 0.3)):
        write_scene_file(tmp_path / "e.rbscene", sample_scene(env))
        assert load_scene_file(tmp_path / "e.rbscene").environment == env
    exact_half = sample_scene()
    exact_half.environment = np.full((2, 4, 3), 0.5, np.float32)
    blob = scene_file_bytes(exact_half)
    manifest = json.loads(zipfile.ZipFile(io.BytesIO(blob)).read(MANIFEST))
    assert manifest["arrays"]["environment"]["dtype"] == "<f2"
    precise = sample_scene()
    precise.environment = np.full((2, 4, 3), 0.1, np.float32)  # not a half float: kept as float32
    manifest = json.loads(zipfile.ZipFile(io.BytesIO(scene_file_bytes(precise))).read(MANIFEST))
    assert manifest["arrays"]["environment"]["dtype"] == "<f4"


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 30), st.integers(0, 2**31 - 1))
def test_any_scene_round_trips_to_the_same_bytes(n_tri, seed):
    rng = np.random.default_rng(seed)
    n_vert = 3 * n_tri
    data = SceneData(
        positions=rng.normal(size=(n_vert, 3)).astype(np.float32),
        triangles=rng.integers(0, n_vert, (n_tri, 3)).astype(np.uint32),
        material_ids=rng.integers(0, 2, n_tri).astype(np.uint32),
        object_ids=rng.integers(0, 3, n_tri).astype(np.uint32),
        materials=[Material(roughness=float(rng.random())), Material(metallic=float(rng.random()))],
        environment=tuple(float(x) for x in rng.random(3)),
        object_names=["a", "b", "c"],
    )
    blob = scene_file_bytes(data)
    assert is_scene_file(blob[:64])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s.rbscene"
        path.write_bytes(blob)
        assert scene_file_bytes(load_scene_file(path)) == blob


def test_negative_environment_texels_are_clamped_with_a_warning(tmp_path: Path):
    data = sample_scene()
    env = data.environment.copy()
    env[0, 0, 0] = -0.002
    env[1, 1, 1] = np.inf
    data.environment = env
    write_scene_file(tmp_path / "s.rbscene", data)
    with pytest.warns(UserWarning, match="clamped 2"):
        got = load_scene_file(tmp_path / "s.rbscene")
    assert got.environment[0, 0, 0] == 0 and got.environment[1, 1, 1] == 0


# -- malformed files ---------------------------------------------------------------------------------------
def rewrite(blob: bytes, *, manifest=None, drop=None, add=None, replace=None, compress=False) -> bytes:
    """A copy of a scene file with its manifest edited (a function of the dict) or entries changed."""
    src = zipfile.ZipFile(io.BytesIO(blob))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == drop:
                continue
            if info.filename == MANIFEST and manifest is not None:
                doc = json.loads(data)
                manifest(doc)
                data = json.dumps(doc).encode()
            if replace and info.filename in replace:
                data = replace[info.filename]
            zf.writestr(info.filename, data,
                        compress_type=zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED)
        for name, data in (add or {}).items():
            zf.writestr(name, data)
    return out.getvalue()


def npy(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, a, version=(1, 0))
    return buf.getvalue()


def set_key(path, value):
    def edit(doc):
        d = doc
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value
    return edit


BAD_POSITIONS = np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]],
                         np.float32)

FIVE_CHANNELS = npy(np.zeros((8, 8, 5), np.uint8))

MALFORMED = {
    "not a zip": (lambda b: b"hello" * 20, "not a readable scene file"),
    "glb": (lambda b: b"glTF" + b"\0" * 100, "not a readable scene file"),
    "format": (lambda b: rewrite(b, manifest=set_key(["format"], "other")), "manifest format"),
    "newer": (lambda b: rewrite(b, manifest=set_key(["version"], 99)), "newer than this reader"),
    "compressed": (lambda b: rewrite(b, compress=True), "compressed"),
    "extra entry": (lambda b: rewrite(b, add={"../evil": b"x"}), "do not match its manifest"),
    "missing entry": (lambda b: rewrite(b, drop="arrays/normals.npy"), "do not match its manifest"),
    "dtype": (lambda b: rewrite(b, manifest=set_key(["arrays", "positions", "dtype"], "|O")), "dtype"),
    "object array": (lambda b: rewrite(b, manifest=set_key(["arrays", "positions", "dtype"], "<f8"),
                                       replace={"arrays/positions.npy": npy(np.zeros((7, 3)))}), "dtype"),
    "shape lie": (lambda b: rewrite(b, manifest=set_key(["arrays", "positions", "shape"], [8, 3])),
                  "manifest says"),
    "nan": (lambda b: rewrite(b, replace={"arrays/positions.npy": npy(BAD_POSITIONS)}), "finite"),
    "index": (lambda b: rewrite(b, replace={"arrays/triangles.npy": npy(np.array(
        [[0, 1, 2], [0, 2, 3], [4, 5, 70]], np.uint32))}), "references vertex 70"),
    "material id": (lambda b: rewrite(b, replace={"arrays/material_ids.npy": npy(np.array(
        [0, 0, 9], np.uint32))}), "material id 9 out of range"),
    "material field": (lambda b: rewrite(b, manifest=set_key(["materials", 0, "roughness"], 3.0)),
                       "roughness must be in"),
    "unknown field": (lambda b: rewrite(b, manifest=set_key(["materials", 0, "__class__"], "x")),
                      "unknown fields"),
    "light kind": (lambda b: rewrite(b, manifest=set_key(["lights", 0, "kind"], "laser")), "light kind"),
    "camera": (lambda b: rewrite(b, manifest=set_key(["cameras", 0, "vfov"], -1)), "vfov"),
    "infinity": (lambda b: rewrite(b, replace={MANIFEST: zipfile.ZipFile(io.BytesIO(b)).read(MANIFEST)
                                               .replace(b'"vfov":0.6', b'"vfov":Infinity')}), "non-finite"),
    "json": (lambda b: rewrite(b, replace={MANIFEST: b"{not json"}), "not valid JSON"),
    "texture index": (lambda b: rewrite(b, manifest=set_key(["materials", 1, "base_color_texture"], 5)),
                      "uses texture 5"),
    "texture channels": (lambda b: rewrite(b, manifest=set_key(["arrays", "texture_0", "shape"], [8, 8, 5]),
                                           replace={"arrays/texture_0.npy": FIVE_CHANNELS}),
                         "1 to 4 channels"),
    "orphan texture": (lambda b: rewrite(b, manifest=set_key(["textures"], [])), "texture_<i>"),
    "texture wrap": (lambda b: rewrite(b, manifest=set_key(["textures", 0, "wrap_u"], "spiral")), "wrap_u"),
    "uvs nan": (lambda b: rewrite(b, replace={"arrays/uvs.npy": npy(np.full((7, 2), np.nan, np.float32))}),
                "uvs must be finite"),
    "strength": (lambda b: rewrite(b, manifest=set_key(["environment", "strength"], -1)), "strength"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_scene_files_are_rejected_clearly(tmp_path: Path, case: str):
    make, message = MALFORMED[case]
    path = tmp_path / "bad.rbscene"
    path.write_bytes(make(scene_file_bytes(sample_scene())))
    with pytest.raises(ValueError, match=message) as err:
        load_scene_file(path)
    assert str(tmp_path) not in str(err.value)


def test_limits_are_enforced(tmp_path: Path):
    path = tmp_path / "s.rbscene"
    write_scene_file(path, sample_scene())
    with pytest.raises(ValueError, match="exceeds the limit"):
        load_scene_file(path, limits=Limits(max_bytes=100))
    with pytest.raises(ValueError, match="exceeds the limits"):
        load_scene_file(path, limits=Limits(max_triangles=2))
    with pytest.raises(FileNotFoundError):
        load_scene_file(tmp_path / "missing.rbscene")


def test_is_scene_file_tells_formats_apart(tmp_path: Path):
    path = tmp_path / "s.rbscene"
    write_scene_file(path, sample_scene())
    assert is_scene_file(path)
    plain_zip = io.BytesIO()
    with zipfile.ZipFile(plain_zip, "w") as zf:
        zf.writestr("other.txt", "x")
    assert not is_scene_file(plain_zip.getvalue())
    assert not is_scene_file(b"glTF" + b"\0" * 60)
    assert not is_scene_file(tmp_path / "missing")


def test_jobs_load_scene_files_by_content(tmp_path: Path):
    """What the CLI, local jobs and evaluation workers do with a scene path: a scene file is recognised by
    its bytes whatever its name, and a worker that gets the pickled handle reloads the same scene."""
    import pickle

    from service import evaluation

    path = tmp_path / "upload.glb"  # a misleading name: the content decides
    write_scene_file(path, sample_scene())
    handle = evaluation.load_scene(path, ship_bytes=True)
    expected = sim_core.Scene.from_scene_data(sample_scene()).content_hash
    assert handle.content_hash == expected
    clone = pickle.loads(pickle.dumps(handle))
    evaluation._SCENES.clear()  # as in a fresh worker process
    path.unlink()  # a worker without the file gets the shipped bytes
    assert clone.get().content_hash == expected
