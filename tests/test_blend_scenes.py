"""Scene generators: build the teapot scene with the real bpy, load it with sim_core's loader, and check
its statistics, camera path and cache behaviour."""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.blender

REPO_ROOT = Path(__file__).resolve().parent.parent

#: Runs scene generators in a fresh Blender process and prints, per scene, one digest of every mesh it made
#: (vertex positions, face corners, faces, loop triangles): what the translation and the glTF export read.
_MESH_DIGEST = """
import hashlib, sys, tempfile
from importlib import import_module
from pathlib import Path
import bpy, numpy as np
for name in sys.argv[1:]:
    with tempfile.TemporaryDirectory() as out:
        import_module("blend_scenes.scenes." + name).build(Path(out))
    h = hashlib.sha256()
    for m in sorted(bpy.data.meshes, key=lambda m: m.name):
        m.calc_loop_triangles()
        h.update(m.name.encode())
        for items, attr, dtype, width in ((m.vertices, "co", np.float32, 3),
                                          (m.loops, "vertex_index", np.int32, 1),
                                          (m.polygons, "loop_start", np.int32, 1),
                                          (m.loop_triangles, "vertices", np.int32, 3)):
            a = np.zeros(len(items) * width, dtype)
            items.foreach_get(attr, a)
            h.update(a.tobytes())
    print("digest", name, h.hexdigest())
"""


@pytest.fixture(scope="module")
def teapot_build(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    pytest.importorskip("bpy")
    from blend_scenes.build import build

    out = tmp_path_factory.mktemp("scenes")
    stats, _chess = build(["teapot", "chess"], out)
    return out, stats


def test_teapot_files_and_stats(teapot_build: tuple[Path, dict]) -> None:
    from sim_core.loaders import load_gltf

    out, stats = teapot_build
    scene_dir = out / "teapot"
    for name in ("scene.blend", "scene.glb", "path.json", "stats.json"):
        assert (scene_dir / name).stat().st_size > 0, name
    sd = load_gltf(scene_dir / "scene.glb")
    # The real teapot (6,320 triangles) plus a 12-triangle floor slab.
    assert stats["triangles"] == sd.triangles.shape[0] == 6320 + 12
    assert stats["lights"] == 1 and sd.lights[0].kind == "point"
    assert sd.lights[0].intensity == pytest.approx(1000.0 / (4 * math.pi), rel=1e-6)
    assert stats["materials"] == 2
    assert "mirror_reflection" in stats["effects"] and "refraction" not in stats["effects"]
    assert json.loads((scene_dir / "stats.json").read_text()) == stats
    # Normalised: about 2 m wide, standing on the floor at z = 0.
    teapot = sd.positions[sd.triangles[sd.object_ids == sd.object_names.index("Teapot")].reshape(-1)]
    extent = teapot.max(axis=0) - teapot.min(axis=0)
    assert extent.max() == pytest.approx(2.0, rel=1e-4)
    assert teapot[:, 2].min() == pytest.approx(0.0, abs=1e-5)


def test_teapot_camera_path(teapot_build: tuple[Path, dict]) -> None:
    import bpy
    from sim_core.loaders import load_gltf

    out, stats = teapot_build
    doc = json.loads((out / "teapot" / "path.json").read_text())
    assert doc["version"] == 1 and doc["fps"] == 30.0
    frames = doc["frames"]
    assert 50 * 30 <= len(frames) <= 60 * 30 + 1 and stats["frames"] == len(frames)
    times = np.array([f["time"] for f in frames])
    assert times[0] == 0.0 and np.allclose(np.diff(times), 1 / 30, atol=1e-5)
    mats = np.array([f["matrix_world"] for f in frames])
    assert mats.shape == (len(frames), 4, 4) and np.all(np.isfinite(mats))
    assert np.allclose(mats[:, 3], [0, 0, 0, 1])
    # Rotations are orthonormal, and the camera keeps looking at the teapot (looks down local -Z).
    rot = mats[:, :3, :3]
    assert np.allclose(rot @ rot.transpose(0, 2, 1), np.eye(3), atol=1e-5)
    to_target = np.array([0.0, 0.0, 0.55]) - mats[:, :3, 3]
    to_target /= np.linalg.norm(to_target, axis=1, keepdims=True)
    forward = -rot[:, :, 2]
    assert np.all(np.sum(forward * to_target, axis=1) > 0.99)
    # Smooth: no jumps between consecutive frames.
    assert np.linalg.norm(np.diff(mats[:, :3, 3], axis=0), axis=1).max() < 0.1
    # Frame 1 of the path equals the camera saved in the .blend and the one in the .glb.
    bpy.ops.wm.open_mainfile(filepath=str(out / "teapot" / "scene.blend"))
    scene = bpy.context.scene
    scene.frame_set(scene.frame_start + 300)
    assert np.allclose(np.array(scene.camera.matrix_world), mats[300], atol=1e-5)
    cam = load_gltf(out / "teapot" / "scene.glb").cameras[0]
    assert np.allclose(cam.matrix_world, mats[0], atol=1e-5)
    assert cam.vfov == pytest.approx(frames[0]["vfov"], rel=1e-5)


def test_teapot_loads_in_the_simulator_and_service(teapot_build: tuple[Path, dict]) -> None:
    import sim_core
    from service.camera_path import CameraPath

    out, stats = teapot_build
    scene = sim_core.Scene.from_gltf(out / "teapot" / "scene.glb")
    assert scene.stats["triangles"] + scene.stats["degenerate_dropped"] == stats["triangles"]
    assert len(scene.cameras) == 1
    path = CameraPath.load(out / "teapot" / "path.json")
    assert len(path) == stats["frames"] and path.fps == 30.0


def test_build_is_deterministic(teapot_build: tuple[Path, dict], tmp_path: Path) -> None:
    from blend_scenes.build import build

    out, _ = teapot_build
    build(["teapot"], tmp_path, force=True)
    for name in ("scene.glb", "scene.rbscene", "path.json"):
        assert (tmp_path / "teapot" / name).read_bytes() == (out / "teapot" / name).read_bytes(), name


def test_uv_sphere_scenes_make_the_same_meshes_in_every_build_process() -> None:
    """Blender's UV-sphere operator ordered its faces by memory address, so the village's lamp globes and
    the artist's glass spheres (and their scene files) changed from one build process to the next (one
    process in two or three agreed): three fresh processes must now make the same meshes."""
    pytest.importorskip("bpy")
    digests: dict[str, set[str]] = {"village": set(), "artist": set()}
    for _ in range(3):
        run = subprocess.run([sys.executable, "-c", _MESH_DIGEST, *digests], cwd=REPO_ROOT,
                             capture_output=True, text=True, timeout=300, check=True)
        for line in run.stdout.splitlines():
            if line.startswith("digest "):
                _, name, digest = line.split()
                digests[name].add(digest)
    assert all(len(d) == 1 for d in digests.values()), digests


def test_uv_sphere_is_closed_and_wound_outwards() -> None:
    pytest.importorskip("bpy")
    import bpy

    from blend_scenes.common import uv_sphere_mesh

    glow = bpy.data.materials.new("SphereTest")
    mesh = uv_sphere_mesh("SphereTest", segments=16, rings=8, radius=0.25, material=glow, smooth=True)
    try:
        mesh.calc_loop_triangles()
        co = np.zeros(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        tris = np.zeros(len(mesh.loop_triangles) * 3, np.int32)
        mesh.loop_triangles.foreach_get("vertices", tris)
        p, t = co.reshape(-1, 3).astype(np.float64), tris.reshape(-1, 3)
        # Blender's UV sphere of the same parameters: 2 poles + 7 rings of 16, 32 fan triangles + 96 quads.
        assert p.shape == (2 + 7 * 16, 3) and t.shape == (32 + 2 * 96, 3) and len(mesh.polygons) == 128
        assert np.allclose(np.linalg.norm(p, axis=1), 0.25, atol=1e-6)
        assert list(mesh.materials) == [glow] and all(poly.use_smooth for poly in mesh.polygons)
        # Closed (every edge in two triangles) and wound outwards: every face normal points away from the
        # centre, and the volume is a little under the sphere's.
        edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
        assert np.all(np.unique(edges, axis=0, return_counts=True)[1] == 2)
        a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
        assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3) > 0)
        volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
        assert 0.9 * 4 / 3 * math.pi * 0.25**3 < volume < 4 / 3 * math.pi * 0.25**3
        with pytest.raises(ValueError, match="segments"):
            uv_sphere_mesh("Bad", segments=2, rings=8, radius=0.25)
    finally:
        bpy.data.meshes.remove(mesh)
        bpy.data.materials.remove(glow)


@pytest.mark.parametrize("name", ["teapot", "chess"])
def test_scene_file_carries_what_the_glb_does(teapot_build: tuple[Path, dict], name: str) -> None:
    """The depsgraph translation (scene.rbscene) and Blender's glTF export agree where both can say it:
    geometry, materials, point / spot / sun lights, camera."""
    from sim_core.loaders import load_gltf
    from sim_core.loaders.scene_file import read_scene_file

    import sim_core

    out, _ = teapot_build
    stats = json.loads((out / name / "stats.json").read_text())
    content = read_scene_file(out / name / "scene.rbscene")
    data, glb = content.data, load_gltf(out / name / "scene.glb")
    blob = (out / name / "scene.rbscene").read_bytes()
    assert stats["translated"]["scene_id"] == hashlib.sha256(blob).hexdigest()
    assert data.triangles.shape == glb.triangles.shape == (stats["triangles"], 3)
    assert sorted(data.object_names) == sorted(glb.object_names)
    assert np.allclose(data.positions.min(axis=0), glb.positions.min(axis=0), atol=1e-5)
    assert np.allclose(data.positions.max(axis=0), glb.positions.max(axis=0), atol=1e-5)

    def area(d) -> float:
        p = d.positions.astype(np.float64)[d.triangles]
        return float(np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum())

    assert area(data) == pytest.approx(area(glb), rel=1e-5)
    by_name = {m.name: m for m in glb.materials}
    for m in data.materials:
        g = by_name[m.name]
        assert m.base_color == pytest.approx(g.base_color, abs=1e-6)
        assert (m.metallic, m.roughness, m.transmission, m.ior) == pytest.approx(
            (g.metallic, g.roughness, g.transmission, g.ior), abs=1e-6)
    lights = {lt.name: lt for lt in glb.lights}
    for lt in data.lights:
        g = lights[lt.name]
        assert (lt.kind, lt.intensity, lt.radius) == (g.kind, pytest.approx(g.intensity, rel=1e-5),
                                                      pytest.approx(g.radius, rel=1e-5))
        assert lt.position == pytest.approx(g.position, abs=1e-5)
        if lt.kind != "point":
            assert lt.direction == pytest.approx(g.direction, abs=1e-5)
    assert np.allclose(data.cameras[0].matrix_world, glb.cameras[0].matrix_world, atol=1e-5)
    assert data.cameras[0].vfov == pytest.approx(glb.cameras[0].vfov, rel=1e-5)
    assert data.environment == pytest.approx(glb.environment, rel=1e-5)
    assert sim_core.Scene.from_scene_file(out / name / "scene.rbscene").stats["triangles"] == \
        sim_core.Scene.from_scene_data(glb).stats["triangles"]


def test_chess_glass_and_mirror_pieces_face_outwards(teapot_build: tuple[Path, dict]) -> None:
    from sim_core.loaders import load_gltf

    out, _ = teapot_build
    stats = json.loads((out / "chess" / "stats.json").read_text())
    assert {"refraction", "mirror_reflection", "instancing"} <= set(stats["effects"])
    sd = load_gltf(out / "chess" / "scene.glb")
    pieces = [i for i, n in enumerate(sd.object_names) if n.startswith(("white_", "black_"))]
    assert len(pieces) == 32
    kinds = {sd.materials[m].name for i in pieces for m in np.unique(sd.material_ids[sd.object_ids == i])}
    assert kinds == {"Glass", "Mirror"}
    p = sd.positions.astype(np.float64)
    for i in pieces:
        # Lathe solids must be closed and wound outwards (refraction decides inside/outside from it):
        # the signed volume is positive, and the same as with every face flipped towards the outside.
        t = sd.triangles[sd.object_ids == i]
        a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
        centre = p[np.unique(t)].mean(axis=0)
        signed = np.einsum("ij,ij->i", a - centre, np.cross(b - centre, c - centre)).sum() / 6.0
        assert signed > 0, sd.object_names[i]
        # Closed: every edge is shared by exactly two triangles (after welding coincident vertices).
        _, weld = np.unique(np.round(p[t.reshape(-1)], 6), axis=0, return_inverse=True)
        tw = weld.reshape(-1, 3)
        edges = np.sort(np.concatenate([tw[:, [0, 1]], tw[:, [1, 2]], tw[:, [2, 0]]]), axis=1)
        edges = edges[edges[:, 0] != edges[:, 1]]
        _, counts = np.unique(edges, axis=0, return_counts=True)
        assert np.all(counts == 2), sd.object_names[i]


def test_cache_skips_unchanged_scene(teapot_build: tuple[Path, dict], capsys: pytest.CaptureFixture) -> None:
    from blend_scenes.build import build, generator_hash, is_cached

    out, stats = teapot_build
    assert is_cached("teapot", out)
    assert stats["generator_hash"] == generator_hash("teapot")
    mtime = (out / "teapot" / "scene.glb").stat().st_mtime_ns
    build(["teapot"], out)
    assert "[cached]" in capsys.readouterr().out
    assert (out / "teapot" / "scene.glb").stat().st_mtime_ns == mtime
    # A stale hash (as after editing the generator) invalidates the cache.
    stats_path = out / "teapot" / "stats.json"
    doc = json.loads(stats_path.read_text())
    stats_path.write_text(json.dumps({**doc, "generator_hash": "0" * 64}))
    assert not is_cached("teapot", out)
    stats_path.write_text(json.dumps(doc))


def test_unknown_scene_is_rejected(tmp_path: Path) -> None:
    from blend_scenes.build import build

    with pytest.raises(ValueError, match="unknown scene"):
        build(["atlantis"], tmp_path)


def test_valley_sky_puts_the_sun_where_the_sun_light_comes_from() -> None:
    from blend_scenes.scenes.valley import SUN_DIRECTION, sky

    img = sky(128, 256)
    assert img.shape == (128, 256, 3) and img.dtype == np.float32 and np.all(np.isfinite(img))
    # sim_core's (and Cycles') equirect convention: column = (0.5 - atan2(y, x) / 2 pi) * W,
    # row = acos(z) / pi * H, row 0 at the zenith.
    to_sun = -SUN_DIRECTION / np.linalg.norm(SUN_DIRECTION)
    col = (0.5 - math.atan2(to_sun[1], to_sun[0]) / (2 * math.pi)) * 256
    row = math.acos(to_sun[2]) / math.pi * 128
    r, c = np.unravel_index(np.argmax(img.sum(axis=2)), img.shape[:2])
    assert abs(r + 0.5 - row) <= 1.5 and abs(c + 0.5 - col) <= 1.5
    assert img[0].mean() < img[60].mean()  # deeper blue at the zenith than near the horizon


def test_tracer_sees_what_blender_sees(teapot_build: tuple[Path, dict]) -> None:
    """End to end: Blender scene -> glTF export -> loader -> path JSON -> Camera.from_blender -> tracer.
    The object the simulator hits at each pixel centre is the one Blender's own ray cast hits."""
    from sim_core.loaders import load_gltf

    import sim_core
    from blend_scenes.verify import pixel_agreement

    out, stats = teapot_build
    for index, agree in pixel_agreement(out / "teapot", [0, 800, stats["frames"] - 1]):
        assert agree > 0.98, f"frame {index}: {agree:.1%} of pixels agree"
    # ... and the comparison is not vacuous: the teapot fills a good part of the view.
    data = load_gltf(out / "teapot" / "scene.glb")
    f = json.loads((out / "teapot" / "path.json").read_text())["frames"][800]
    cam = sim_core.Camera.from_blender(np.array(f["matrix_world"]), f["vfov"], 48, 27)
    result = sim_core.render(sim_core.Scene.from_scene_data(data), cam, sim_core.RenderSettings())
    ids = result.aovs["object_id"]
    assert 0.05 < np.mean(ids == data.object_names.index("Teapot")) < 0.8
