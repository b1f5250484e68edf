"""OBJ loader: syntax corner cases, MTL materials, bad inputs, and the bundled meshes against Blender's
own OBJ importer (same Y-up to Z-up convention)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sim_core.loaders import load_obj

QUAD = """# a quad and a triangle in two objects, negative indices, normals, a material library
mtllib scene.mtl
o Quad
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vn 0 0 1
usemtl Glass
f 1//1 2//1 3//1 4//1
o Tri
v 0 0 1
v 1 0 1
v 0 1 1
usemtl Mirror
f -3 -2 -1
"""
MTL = """newmtl Glass
Kd 0.9 0.9 1.0
Ni 1.45
d 0.0
Ns 900
newmtl Mirror
Kd 0.8 0.8 0.8
Pm 1.0
Pr 0.05
"""


def _write(tmp_path: Path, text: str, mtl: str | None = None) -> Path:
    path = tmp_path / "scene.obj"
    path.write_text(text)
    if mtl is not None:
        (tmp_path / "scene.mtl").write_text(mtl)
    return path


def test_polygons_objects_materials(tmp_path: Path) -> None:
    sd = load_obj(_write(tmp_path, QUAD, MTL))
    assert sd.triangles.shape == (3, 3)
    assert sd.object_names == ["Quad", "Tri"]
    assert sd.object_ids.tolist() == [0, 0, 1]
    names = [sd.materials[i].name for i in sd.material_ids]
    assert names == ["Glass", "Glass", "Mirror"]
    glass = sd.materials[sd.material_ids[0]]
    assert glass.transmission == pytest.approx(1.0) and glass.ior == pytest.approx(1.45)
    assert glass.roughness == pytest.approx(1.0 - np.sqrt(0.9), rel=1e-6)
    mirror = sd.materials[sd.material_ids[2]]
    assert mirror.metallic == 1.0 and mirror.roughness == pytest.approx(0.05)
    # Y-up file -> Z-up world: (x, y, z) -> (x, -z, y); the quad's +Z normal becomes -Y.
    tri = sd.positions[sd.triangles[2]]
    assert np.allclose(tri, [[0, -1, 0], [1, -1, 0], [0, -1, 1]])
    quad_vertices = np.unique(sd.triangles[:2])
    assert np.allclose(sd.normals[quad_vertices], [0.0, -1.0, 0.0])


def test_z_up_keeps_coordinates(tmp_path: Path) -> None:
    sd = load_obj(_write(tmp_path, QUAD, MTL), up_axis="Z")
    assert np.allclose(sd.positions[sd.triangles[2]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]])


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        load_obj(tmp_path / "none.obj")


def test_missing_material_library(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="material library"):
        load_obj(_write(tmp_path, QUAD))


@pytest.mark.parametrize("library", ["../outside.mtl", "ABSOLUTE", "link.mtl"])
def test_material_library_stays_inside_the_obj_folder(tmp_path: Path, library: str) -> None:
    outside = tmp_path / "outside.mtl"
    outside.write_text("newmtl red\nKd 1 0 0\n")
    folder = tmp_path / "model"
    folder.mkdir()
    (folder / "link.mtl").symlink_to(outside)
    library = library.replace("ABSOLUTE", str(outside))
    text = QUAD.replace("mtllib scene.mtl", f"mtllib {library}")
    with pytest.raises(ValueError, match="outside the scene's folder"):
        load_obj(_write(folder, text))


@pytest.mark.parametrize(
    "text,match",
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "out of range"),
        ("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "NaN or Inf"),
        ("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", "NaN or Inf"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
        ("", "no faces"),
        ("v 0 0\n", "needs 3"),
        ("v 0 0 x\n", "malformed"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", "malformed face"),
    ],
)
def test_bad_inputs(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        load_obj(_write(tmp_path, text))


def test_binary_file_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "x.obj"
    path.write_bytes(b"\xff\xfe\x00\x81binary")
    with pytest.raises(ValueError):
        load_obj(path)


def test_bundled_meshes_counts(models_dir: Path) -> None:
    for name, tris in [("teapot.obj", 6320), ("stanford-bunny.obj", 69451), ("spot.obj", 5856)]:
        sd = load_obj(models_dir / name)
        assert sd.triangles.shape == (tris, 3), name
        assert sd.triangles.max() < sd.positions.shape[0]
        assert np.all(np.isfinite(sd.positions))


def test_fast_and_general_parsers_agree(models_dir: Path, tmp_path: Path) -> None:
    """Plain files take a vectorised path; a group line forces the general parser: same mesh."""
    text = (models_dir / "teapot.obj").read_text()
    fast = load_obj(models_dir / "teapot.obj")
    (tmp_path / "grouped.obj").write_text("g teapot\n" + text)
    general = load_obj(tmp_path / "grouped.obj")
    assert np.array_equal(fast.positions, general.positions)
    assert np.array_equal(fast.triangles, general.triangles)
    assert fast.object_names == ["teapot"] and general.object_names == ["teapot"]


def test_fast_path_falls_back_for_errors(tmp_path: Path) -> None:
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")
    with pytest.raises(ValueError, match=r"bad\.obj:4: vertex index 9 out of range"):
        load_obj(path)


@pytest.mark.blender
@pytest.mark.parametrize("name", ["teapot.obj", "spot.obj"])
def test_matches_blender_obj_importer(models_dir: Path, name: str) -> None:
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.wm.obj_import(filepath=str(models_dir / name))  # defaults: forward -Z, up Y
    objs = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    assert len(objs) == 1
    mesh = objs[0].data
    co = np.zeros(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    m = np.array(objs[0].matrix_world)
    theirs = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    mesh.calc_loop_triangles()
    sd = load_obj(models_dir / name)
    assert len(mesh.loop_triangles) == sd.triangles.shape[0]
    mine = sd.positions.astype(np.float64)
    # Same point sets (Blender merges nothing; we split per normal, so compare unique rows).
    a = np.unique(np.round(mine, 5), axis=0)
    b = np.unique(np.round(theirs, 5), axis=0)
    assert a.shape == b.shape and np.allclose(a, b, atol=2e-5)
    # Same total area: the triangulation covers the same surface.
    def area(p: np.ndarray, t: np.ndarray) -> float:
        cross = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        return float(np.linalg.norm(cross, axis=1).sum() / 2)

    tris = np.zeros(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    expected = area(theirs, tris.reshape(-1, 3))
    assert area(mine, sd.triangles.astype(np.int64)) == pytest.approx(expected, rel=1e-6)
