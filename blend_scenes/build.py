"""Build the test scenes: ``python -m blend_scenes.build [--scene NAME ...] [--out DIR] [--force]``.

For each scene it writes ``<out>/<name>/{scene.blend, scene.glb, scene.rbscene, path.json, stats.json}``
(plus any extra file such as the valley's environment EXR). ``scene.rbscene`` is the add-on's depsgraph
translation at render level (what the add-on's jobs optimise and the render engine renders; summarised as
``translated`` in stats.json); ``scene.glb`` is what a REST user would upload. Builds are cached: a scene
is rebuilt only when the hash of its generator, the shared helpers, this driver, the translator, the scene
file format and the bundled models it names changes (stored in stats.json, which is written last, so an
interrupted build is redone). The other statistics are measured on the exported .glb through sim_core's own
loader.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import os
import re
import struct
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from sim_core.loaders import load_gltf

import sim_core
from service.camera_path import CameraPath

from .scenes import SCENES

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_DIR.parent
DEFAULT_OUT = PACKAGE_DIR / "build"
#: What scene.rbscene depends on besides the generator: the depsgraph translator and the file format.
_SCENE_FILE_PACKAGE = REPO_ROOT / "sim_core" / "python" / "sim_core" / "loaders" / "scene_file"
TRANSLATOR_SOURCES = (REPO_ROOT / "addon" / "translate.py", REPO_ROOT / "addon" / "node_trees.py",
                      *sorted((REPO_ROOT / "addon" / "core" / "scene_translation").glob("*.py")),
                      *sorted(_SCENE_FILE_PACKAGE.glob("*.py")))
SCENE_FILES = ("scene.blend", "scene.glb", "scene.rbscene", "path.json", "stats.json")
#: The add-on's helpers the build uses (path sampling, fov, glTF export): part of every scene's hash.
ADDON_SOURCES = tuple(REPO_ROOT / f for f in ("addon/camera_path.py", "addon/scene_export.py",
                                              "addon/core/path_sampling.py", "service/store/camera.py"))


def generator_hash(name: str) -> str:
    """Hash of everything that determines a scene's content (sources and the models it loads)."""
    h = hashlib.sha256()
    gen = PACKAGE_DIR / "scenes" / f"{name}.py"
    sources = [gen, PACKAGE_DIR / "common.py", PACKAGE_DIR / "build.py", *TRANSLATOR_SOURCES, *ADDON_SOURCES]
    text = gen.read_text()
    models = sorted(set(re.findall(r"[\"']([\w-]+\.obj)[\"']", text)))  # quoted model file names
    sources += [REPO_ROOT / "assets" / "models" / m for m in models]
    for src in sources:
        h.update(src.name.encode())
        h.update(src.read_bytes())
    return h.hexdigest()


def is_cached(name: str, out_dir: Path) -> bool:
    scene_dir = out_dir / name
    stats_path = scene_dir / "stats.json"
    if not all((scene_dir / f).is_file() for f in SCENE_FILES):
        return False
    try:
        stats = json.loads(stats_path.read_text())
    except (OSError, json.JSONDecodeError):
        return False
    if not all((scene_dir / f).is_file() for f in stats.get("extra_files", [])):
        return False
    return stats.get("generator_hash") == generator_hash(name)


def scene_statistics(glb: Path) -> dict[str, Any]:
    """Counts and effects of the exported scene, as sim_core's loader reads it."""
    sd = load_gltf(glb)
    simulated = sim_core.Scene.from_scene_data(sd)  # the scene must load in the simulator, BVH and all
    raw = _glb_json(glb)
    mesh_nodes = [n for n in raw.get("nodes", []) if "mesh" in n]
    unique_meshes = len({n["mesh"] for n in mesh_nodes})
    used = sorted({int(i) for i in np.unique(sd.material_ids)})
    mats = [sd.materials[i] for i in used]
    effects = []
    if sd.lights:
        effects.append("shadows")
    if any(lt.radius > 0 for lt in sd.lights):
        effects.append("soft_shadows")
    if len(sd.lights) > 1:
        effects.append("multiple_lights")
    if any(m.metallic >= 0.5 and m.roughness <= 0.2 for m in mats):
        effects.append("mirror_reflection")
    if any(m.metallic > 0.0 and 0.2 < m.roughness < 0.7 for m in mats) or any(
        m.metallic < 0.5 and m.roughness < 0.3 and m.transmission == 0 for m in mats
    ):
        effects.append("glossy_reflection")
    if any(m.transmission > 0 for m in mats):
        effects.append("refraction")
    if any(max(m.emission) > 0 for m in mats):
        effects.append("emission")
    if isinstance(sd.environment, np.ndarray):
        effects.append("environment_map")
    elif sd.environment is not None:
        effects.append("constant_environment")
    if unique_meshes < len(mesh_nodes):
        effects.append("instancing")
    return {
        "triangles": int(sd.triangles.shape[0]),
        "vertices": int(sd.positions.shape[0]),
        "materials": len(used),
        "lights": len(sd.lights),
        "light_kinds": sorted({lt.kind for lt in sd.lights}),
        "objects": len(sd.object_names),
        "unique_meshes": unique_meshes,
        "effects": effects,
        "simulator_effects": list(simulated.stats["effects"]),
        "degenerate_dropped": int(simulated.stats["degenerate_dropped"]),
        "bounds": [sd.positions.min(axis=0).round(3).tolist(), sd.positions.max(axis=0).round(3).tolist()],
    }


def _glb_json(glb: Path) -> dict[str, Any]:
    data = glb.read_bytes()
    (length,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + length])


def compact(path: CameraPath) -> CameraPath:
    """The path as the scene files keep it: times to the microsecond, matrices to 7 decimals (small files
    that stay byte-stable across platforms)."""
    doc = path.to_dict()
    for frame in doc["frames"]:
        frame["time"] = round(frame["time"], 6)
        frame["matrix_world"] = [[round(v, 7) for v in row] for row in frame["matrix_world"]]
    return CameraPath.from_dict(doc)


def stats_line(name: str, stats: dict[str, Any]) -> str:
    return (f"{name}: {stats['triangles']:,} triangles, {stats['materials']} materials, "
            f"{stats['lights']} lights, {stats['objects']} objects, {stats['frames']} frames "
            f"({stats['duration_s']:.0f} s); effects: {', '.join(stats['effects'])}")


def build_scene(name: str, out_dir: Path) -> dict[str, Any]:
    """Run one generator in this process's bpy and write its files; returns the statistics."""
    # lazy: bpy (and what imports it) only after build() has kept Blender's user configuration out of
    # the home directory
    import bpy

    from addon.camera_path import sample_animation
    from addon.scene_export import export_glb

    from . import common

    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; choose from {', '.join(SCENES)}")
    scene_dir = out_dir / name
    scene_dir.mkdir(parents=True, exist_ok=True)
    (scene_dir / "stats.json").unlink(missing_ok=True)
    start = time.perf_counter()
    module = importlib.import_module(f"blend_scenes.scenes.{name}")
    spec: common.SceneSpec = module.build(scene_dir)
    clearance, problems = common.camera_clearance(spec.camera)
    if problems:
        raise RuntimeError(f"{name}: camera path clips geometry: {'; '.join(problems[:6])}")
    path = compact(sample_animation(bpy.context.scene, spec.camera))
    path.save(scene_dir / "path.json")
    export_glb(bpy.context.scene, scene_dir / "scene.glb")
    translated = common.export_scene_file(scene_dir / "scene.rbscene")
    bpy.ops.wm.save_as_mainfile(filepath=str(scene_dir / "scene.blend"), compress=True, check_existing=False)
    stats = {"name": name, "description": spec.description, **scene_statistics(scene_dir / "scene.glb")}
    stats.update({
        "frames": len(path),
        "fps": path.fps,
        "duration_s": path.frames[-1].time,
        "resolution": list(path.frames[0].resolution),
        "extra_files": [p.name for p in spec.extra_files],
        "translated": translated,
        "camera_min_clearance_m": round(clearance, 3),
        "blender_version": bpy.app.version_string,
        "build_seconds": round(time.perf_counter() - start, 2),
        "generator_hash": generator_hash(name),
    })
    stats["summary"] = stats_line(name, stats)
    (scene_dir / "stats.json").write_text(json.dumps(stats, indent=2) + "\n")
    return stats


_BLENDER_USER: list[tempfile.TemporaryDirectory] = []


def private_blender_user_folder() -> None:
    """Keep Blender's user config out of the home directory: a folder of this process's own, removed when
    it ends (before bpy is imported; a folder already chosen is kept)."""
    if "BLENDER_USER_RESOURCES" not in os.environ:
        _BLENDER_USER.append(tempfile.TemporaryDirectory(prefix="blend-scenes-"))
        os.environ["BLENDER_USER_RESOURCES"] = _BLENDER_USER[-1].name


def build(names: list[str] | None = None, out_dir: Path = DEFAULT_OUT, force: bool = False) -> list[dict]:
    """Build (or reuse) the named scenes, all by default; returns their statistics."""
    if "bpy" not in sys.modules:
        private_blender_user_folder()
    results = []
    for name in names or list(SCENES):
        if name not in SCENES:
            raise ValueError(f"unknown scene {name!r}; choose from {', '.join(SCENES)}")
        if not force and is_cached(name, out_dir):
            stats = json.loads((out_dir / name / "stats.json").read_text())
            print(f"[cached] {stats['summary']}", flush=True)
        else:
            stats = build_scene(name, out_dir)
            print(f"[built {stats['build_seconds']:.1f} s] {stats['summary']}", flush=True)
        results.append(stats)
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m blend_scenes.build", description=__doc__.splitlines()[0])
    parser.add_argument("--scene", action="append", help="scene to build (repeatable); default: all")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default: %(default)s)")
    parser.add_argument("--force", action="store_true", help="rebuild even when cached")
    args = parser.parse_args(argv)
    try:
        build(args.scene, args.out, args.force)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
