"""Scene construction: bad input raises clear errors; stats and content hash."""

from __future__ import annotations

import numpy as np
import pytest

import sim_core
from sim_core import Light, Material

POS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
TRI = np.array([[0, 1, 2], [1, 3, 2]], np.int64)


def test_nan_vertex_raises():
    pos = POS.copy()
    pos[2, 1] = np.nan
    with pytest.raises(ValueError, match="positions must be finite"):
        sim_core.Scene.from_arrays(pos, TRI)


def test_inf_vertex_raises():
    pos = POS.copy()
    pos[0, 0] = np.inf
    with pytest.raises(ValueError, match="finite"):
        sim_core.Scene.from_arrays(pos, TRI)


def test_out_of_range_index_raises():
    with pytest.raises(ValueError, match="references vertex 4"):
        sim_core.Scene.from_arrays(POS, np.array([[0, 1, 4]]))


def test_negative_index_raises():
    with pytest.raises(ValueError, match="non-negative"):
        sim_core.Scene.from_arrays(POS, np.array([[0, 1, -1]]))


@pytest.mark.parametrize(
    ("pos", "tri"), [(np.zeros((0, 3)), np.zeros((0, 3), int)), (POS, np.zeros((0, 3), int))]
)
def test_empty_scene_raises(pos, tri):
    with pytest.raises(ValueError, match="empty scene"):
        sim_core.Scene.from_arrays(pos, tri)


def test_all_degenerate_is_empty():
    with pytest.raises(ValueError, match="degenerate"):
        sim_core.Scene.from_arrays(POS, np.array([[0, 1, 1], [0, 0, 0]]))


def test_bad_shapes_and_ids_raise():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        sim_core.Scene.from_arrays(POS[:, :2], TRI)
    with pytest.raises(ValueError, match="material id 1 out of range"):
        sim_core.Scene.from_arrays(POS, TRI, material_ids=[0, 1])
    with pytest.raises(ValueError, match="one entry per triangle"):
        sim_core.Scene.from_arrays(POS, TRI, object_ids=[0])
    with pytest.raises(ValueError, match="one row per vertex"):
        sim_core.Scene.from_arrays(POS, TRI, normals=np.ones((2, 3)))
    with pytest.raises(ValueError, match="environment"):
        sim_core.Scene.from_arrays(POS, TRI, environment=(1.0, 2.0))
    # A map's non-finite or negative texels are clamped with a warning (HDRIs hold such texels), not rejected.
    with pytest.warns(UserWarning, match="environment map: clamped 0 value"):
        sim_core.Scene.from_arrays(POS, TRI, environment=np.full((4, 8, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="materials must be"):
        sim_core.Scene.from_arrays(POS, TRI, materials=["red"])  # type: ignore[list-item]
    with pytest.raises(ValueError, match="integers"):
        sim_core.Scene.from_arrays(POS, np.array([[0, 1, 2.5]]))


def test_unreadable_files_raise(tmp_path):
    with pytest.raises(FileNotFoundError):
        sim_core.Scene.from_obj(tmp_path / "missing.obj")
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 3\n")
    with pytest.raises(ValueError):
        sim_core.Scene.from_obj(bad)
    with pytest.raises((FileNotFoundError, ValueError)):
        sim_core.Scene.from_gltf(tmp_path / "missing.glb")


def test_stats_and_hash():
    mats = [
        Material(base_color=(1, 0, 0)),
        Material(metallic=1.0, roughness=0.2),
        Material(transmission=1.0, ior=1.45),
    ]
    lights = [Light(kind="point", position=(0, 0, 3), intensity=10, radius=0.1)]
    pos = np.vstack([POS, [[5, 5, 5]]]).astype(np.float32)
    tri = np.vstack([TRI, [[0, 1, 1]]])
    a = sim_core.Scene.from_arrays(
        pos, tri, material_ids=[0, 1, 2], object_ids=[3, 7, 7], materials=mats, lights=lights
    )
    s = a.stats
    assert s["triangles"] == 2 and s["degenerate_dropped"] == 1
    assert s["materials"] == 3 and s["lights"] == 1 and s["objects"] == 2
    assert {"reflection", "glossy", "refraction", "soft_shadows", "direct_light"} <= set(s["effects"])
    b = sim_core.Scene.from_arrays(
        pos, tri, material_ids=[0, 1, 2], object_ids=[3, 7, 7], materials=mats, lights=lights
    )
    assert a.content_hash == b.content_hash and len(a.content_hash) == 64
    c = sim_core.Scene.from_arrays(pos, tri, material_ids=[0, 1, 2], object_ids=[3, 7, 7], materials=mats)
    assert c.content_hash != a.content_hash
    d = sim_core.Scene.from_arrays(
        pos + np.float32(1e-3),
        tri,
        material_ids=[0, 1, 2],
        object_ids=[3, 7, 7],
        materials=mats,
        lights=lights,
    )
    assert d.content_hash != a.content_hash


def test_from_obj_matches_from_arrays(models_dir):
    from sim_core.loaders import load_obj

    scene = sim_core.Scene.from_obj(models_dir / "teapot.obj")
    data = load_obj(models_dir / "teapot.obj")
    assert scene.stats["triangles"] + scene.stats["degenerate_dropped"] == len(data.triangles)
    assert scene.content_hash == sim_core.Scene.from_scene_data(data).content_hash


def test_load_exr_round_trip_and_errors(tmp_path):
    import OpenEXR

    sky = np.random.default_rng(0).random((8, 16, 3)).astype(np.float32)
    path = tmp_path / "sky.exr"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": sky}) as f:
        f.write(str(path))
    loaded = sim_core.load_exr(path)
    np.testing.assert_array_equal(loaded, sky)
    scene = sim_core.Scene.from_arrays(POS, TRI, environment=loaded)
    assert "environment_map" in scene.stats["effects"]
    with pytest.raises(FileNotFoundError):
        sim_core.load_exr(tmp_path / "missing.exr")
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an exr")
    with pytest.raises(ValueError):
        sim_core.load_exr(junk)
