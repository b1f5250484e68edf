"""Shared bpy helpers for the scene generators: materials, meshes, lights, animated cameras. Sampling the
camera path and the glTF export are the add-on's own (``addon.camera_path``, ``addon.scene_export``).

Everything here is deterministic: geometry comes from closed-form functions or seeded numpy generators,
never from Blender's random operators, nor from operators whose output order depends on memory addresses
(the UV-sphere primitive: use ``uv_sphere_mesh``). Generators import this module, so changing it rebuilds
every scene (build.py hashes it together with each generator).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import bpy
import numpy as np
from mathutils import Euler, Matrix, Vector
from sim_core.loaders.scene_file import write_scene_file

from addon.translate import translate_for_render

REPO_ROOT = Path(__file__).resolve().parent.parent
MODELS_DIR = REPO_ROOT / "assets" / "models"
FPS = 30
RESOLUTION = (1280, 720)
#: Scene custom property exported as glTF scene extras; sim_core's glTF loader reads it.
ENVIRONMENT_KEY = "render_budget_environment"
#: Light custom property exported as glTF light extras: the emitter radius (soft shadows).
LIGHT_RADIUS_KEY = "render_budget_radius"

Vec3 = tuple[float, float, float]


@dataclass
class SceneSpec:
    """What a generator hands back to the driver besides the Blender scene itself."""

    name: str
    description: str
    camera: bpy.types.Object
    duration_s: float
    extra_files: list[Path] = field(default_factory=list)  # written next to scene.glb (e.g. the EXR)


def reset() -> None:
    """Start from an empty factory scene so nothing from a previous build leaks in."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.fps = FPS
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100


# --------------------------------------------------------------------------------------------------
# Materials
# --------------------------------------------------------------------------------------------------


def principled(name: str, base: Sequence[float] = (0.8, 0.8, 0.8), *, metallic: float = 0.0,
               roughness: float = 0.5, transmission: float = 0.0, ior: float = 1.5,
               emission: Sequence[float] | None = None, emission_strength: float = 0.0) -> bpy.types.Material:
    """A Principled BSDF material: these inputs are what the glTF exporter writes (core PBR,
    KHR_materials_transmission, KHR_materials_ior, KHR_materials_emissive_strength)."""
    mat = bpy.data.materials.new(name)
    if not mat.node_tree:  # Blender < 5 needs use_nodes; 5.x always has a node tree
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*base[:3], 1.0)
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Transmission Weight"].default_value = transmission
    bsdf.inputs["IOR"].default_value = ior
    if emission is not None and emission_strength > 0:
        bsdf.inputs["Emission Color"].default_value = (*emission[:3], 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission_strength
    mat.diffuse_color = (*base[:3], 1.0)
    return mat


# --------------------------------------------------------------------------------------------------
# Meshes
# --------------------------------------------------------------------------------------------------


def link(obj: bpy.types.Object, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def mesh_from_arrays(name: str, vertices: np.ndarray, faces: np.ndarray | list[Sequence[int]],
                     material: bpy.types.Material | Sequence[bpy.types.Material] | None = None, *,
                     material_indices: np.ndarray | None = None, smooth: bool = False) -> bpy.types.Mesh:
    """Mesh datablock from numpy arrays (fast path through foreach_set, fine for 10^6 faces)."""
    verts = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
    if isinstance(faces, np.ndarray):
        loops = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1)
        sizes = np.full(faces.shape[0], faces.shape[1], dtype=np.int32)
    else:
        loops = np.asarray([i for f in faces for i in f], dtype=np.int32)
        sizes = np.asarray([len(f) for f in faces], dtype=np.int32)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int32)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", verts.reshape(-1))
    mesh.loops.add(len(loops))
    mesh.loops.foreach_set("vertex_index", loops)
    mesh.polygons.add(len(sizes))
    mesh.polygons.foreach_set("loop_start", starts)
    mesh.polygons.foreach_set("use_smooth", np.full(len(sizes), smooth, dtype=bool))
    mats = [] if material is None else ([material] if isinstance(material, bpy.types.Material) else material)
    for m in mats:
        mesh.materials.append(m)
    if material_indices is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(material_indices, dtype=np.int32))
    mesh.update(calc_edges=True)
    mesh.validate()
    return mesh


def add_object(name: str, data: bpy.types.ID | None, location: Sequence[float] = (0, 0, 0),
               rotation: Sequence[float] = (0, 0, 0), scale: Sequence[float] | float = 1.0,
               collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    obj.rotation_euler = rotation
    obj.scale = (scale, scale, scale) if isinstance(scale, (int, float)) else scale
    return link(obj, collection)


def box_mesh(name: str, size: Sequence[float], material: bpy.types.Material | None = None) -> bpy.types.Mesh:
    """Axis-aligned box centred on the origin, outward normals."""
    sx, sy, sz = (s / 2 for s in size)
    v = np.array([[-sx, -sy, -sz], [sx, -sy, -sz], [sx, sy, -sz], [-sx, sy, -sz],
                  [-sx, -sy, sz], [sx, -sy, sz], [sx, sy, sz], [-sx, sy, sz]])
    f = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
    return mesh_from_arrays(name, v, f, material)


def box(name: str, size: Sequence[float], location: Sequence[float], material: bpy.types.Material,
        rotation: Sequence[float] = (0, 0, 0)) -> bpy.types.Object:
    return add_object(name, box_mesh(name, size, material), location, rotation)


def grid_mesh(name: str, heights: np.ndarray, size_x: float, size_y: float,
              material: bpy.types.Material | None = None, smooth: bool = True) -> bpy.types.Mesh:
    """Height field (ny, nx) centred on the origin as a quad grid (2 triangles per cell)."""
    ny, nx = heights.shape
    xs = np.linspace(-size_x / 2, size_x / 2, nx)
    ys = np.linspace(-size_y / 2, size_y / 2, ny)
    gx, gy = np.meshgrid(xs, ys)
    verts = np.stack([gx, gy, heights], axis=-1).reshape(-1, 3)
    idx = np.arange(nx * ny).reshape(ny, nx)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1).reshape(-1, 4)
    return mesh_from_arrays(name, verts, quads, material, smooth=smooth)


def uv_sphere_mesh(name: str, segments: int, rings: int, radius: float,
                   material: bpy.types.Material | None = None, smooth: bool = False) -> bpy.types.Mesh:
    """A UV sphere centred on the origin in closed form: a triangle fan at each pole, quads between the
    rings, wound outwards. Not Blender's UV-sphere operator (``primitive_uv_sphere_add``,
    ``bmesh.ops.create_uvsphere``): its spin and merge leave the faces in an order that depends on memory
    addresses, so the triangle arrays (and scene.rbscene) differed from one build process to the next."""
    if segments < 3 or rings < 2:
        raise ValueError(f"a UV sphere needs >= 3 segments and >= 2 rings, got {segments} and {rings}")
    polar = np.pi * np.arange(1, rings) / rings
    azimuth = 2 * np.pi * np.arange(segments) / segments
    ring_verts = np.stack([np.outer(np.sin(polar), np.cos(azimuth)), np.outer(np.sin(polar), np.sin(azimuth)),
                           np.repeat(np.cos(polar)[:, None], segments, axis=1)], axis=-1).reshape(-1, 3)
    verts = radius * np.concatenate([[[0.0, 0.0, 1.0]], ring_verts, [[0.0, 0.0, -1.0]]])
    top, bottom = 0, len(verts) - 1
    ring = np.arange(1, 1 + (rings - 1) * segments).reshape(rings - 1, segments)
    nxt = np.roll(ring, -1, axis=1)  # the next vertex around each ring (counter-clockwise seen from +Z)
    faces: list[tuple[int, ...]] = [(top, int(a), int(b)) for a, b in zip(ring[0], nxt[0], strict=True)]
    for k in range(rings - 2):  # quads between ring k and ring k + 1
        faces += [(int(a), int(c), int(d), int(b))
                  for a, b, c, d in zip(ring[k], nxt[k], ring[k + 1], nxt[k + 1], strict=True)]
    faces += [(bottom, int(b), int(a)) for a, b in zip(ring[-1], nxt[-1], strict=True)]
    return mesh_from_arrays(name, verts, faces, material, smooth=smooth)


def lathe(name: str, profile: Sequence[tuple[float, float]], material: bpy.types.Material,
          steps: int = 32) -> bpy.types.Mesh:
    """A turned solid: the (radius, height) profile, bottom to top, spun around Z by a Screw modifier
    on a temporary object; the modifier is applied so instances can share the resulting mesh."""
    prof = bpy.data.meshes.new(name + "_profile")
    prof.from_pydata([(r, 0.0, z) for r, z in profile], [(i, i + 1) for i in range(len(profile) - 1)], [])
    tmp = link(bpy.data.objects.new(name + "_lathe", prof))
    mod = tmp.modifiers.new("screw", "SCREW")
    mod.axis = "Z"
    mod.steps = mod.render_steps = steps
    mod.use_merge_vertices = True
    mod.merge_threshold = 1e-5
    mod.use_smooth_shade = True
    mod.use_normal_flip = True  # a profile walked upwards would face inwards otherwise
    deps = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(tmp.evaluated_get(deps), depsgraph=deps)
    mesh.name = name
    bpy.data.objects.remove(tmp)
    bpy.data.meshes.remove(prof)
    mesh.materials.clear()
    mesh.materials.append(material)
    return mesh


def import_obj(path: Path, name: str, material: bpy.types.Material) -> bpy.types.Object:
    """Blender's own OBJ importer (forward -Z, up Y: the file's Y-up becomes Z-up)."""
    before = set(bpy.data.objects)
    bpy.ops.wm.obj_import(filepath=str(path))
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if len(new) != 1:
        raise RuntimeError(f"expected one mesh from {path.name}, got {len(new)}")
    obj = new[0]
    obj.name = obj.data.name = name
    obj.data.transform(obj.matrix_world)  # bake the importer's axis conversion into the vertices
    obj.matrix_world = Matrix.Identity(4)
    obj.data.materials.clear()
    obj.data.materials.append(material)
    for poly in obj.data.polygons:
        poly.use_smooth = True
    return obj


def normalise(obj: bpy.types.Object, size: float, location: Sequence[float] = (0, 0, 0)) -> None:
    """Scale the mesh data so its largest extent is `size`, centred in XY at `location`, resting on its
    z (the transform stays clean for the exporter)."""
    co = np.zeros(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    lo, hi = co.min(axis=0), co.max(axis=0)
    s = size / float((hi - lo).max())
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    co = (co - centre) * s
    obj.data.vertices.foreach_set("co", co.reshape(-1).astype(np.float32))
    obj.data.update()
    obj.location = location


# --------------------------------------------------------------------------------------------------
# Lights and world
# --------------------------------------------------------------------------------------------------


def _light(name: str, kind: str, watts: float, location: Sequence[float], rotation: Sequence[float],
           color: Vec3, radius: float) -> bpy.types.Object:
    data = bpy.data.lights.new(name, kind)
    data.energy = watts
    data.color = color
    if kind != "SUN":
        data.shadow_soft_size = radius  # metres
        data[LIGHT_RADIUS_KEY] = radius
    else:
        data.angle = 2.0 * radius  # Blender: angular diameter; we export the angular radius
        data[LIGHT_RADIUS_KEY] = radius
    return add_object(name, data, location, rotation)


def point_light(name: str, location: Sequence[float], watts: float, color: Vec3 = (1.0, 1.0, 1.0),
                radius: float = 0.1) -> bpy.types.Object:
    return _light(name, "POINT", watts, location, (0, 0, 0), color, radius)


def spot_light(name: str, location: Sequence[float], target: Sequence[float], watts: float,
               angle_deg: float = 45.0, color: Vec3 = (1.0, 1.0, 1.0),
               radius: float = 0.05) -> bpy.types.Object:
    rot = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    obj = _light(name, "SPOT", watts, location, rot, color, radius)
    obj.data.spot_size = math.radians(angle_deg)
    obj.data.spot_blend = 0.2
    return obj


def sun_light(name: str, direction: Sequence[float], strength: float, color: Vec3 = (1.0, 0.97, 0.9),
              angle_deg: float = 0.5) -> bpy.types.Object:
    """Sun shining along `direction` (strength in W/m^2)."""
    rot = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    return _light(name, "SUN", strength, (0, 0, 10), rot, color, math.radians(angle_deg) / 2.0)


def world_color(rgb: Vec3) -> None:
    """Constant background: set in Blender's world and exported as a scene extra for the simulator."""
    world = bpy.data.worlds.new("World")
    bpy.context.scene.world = world
    world.color = rgb
    bg = world.node_tree.nodes.get("Background") if world.node_tree else None
    if bg is not None:
        bg.inputs["Color"].default_value = (*rgb, 1.0)
    bpy.context.scene[ENVIRONMENT_KEY] = list(rgb)


def world_exr(path: Path, strength: float = 1.0, rotation_z: float = 0.0) -> bpy.types.Image:
    """Equirectangular environment: Blender world node tree (Environment Texture, turned by a Mapping node's
    Z rotation when ``rotation_z`` is not 0) + scene extra naming the file (relative); returns the image."""
    world = bpy.data.worlds.new("World")
    bpy.context.scene.world = world
    if not world.node_tree:
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(path))
    bg = nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    links.new(env.outputs["Color"], bg.inputs["Color"])
    if rotation_z:
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
        links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    bpy.context.scene[ENVIRONMENT_KEY] = path.name
    return env.image


# --------------------------------------------------------------------------------------------------
# Camera path
# --------------------------------------------------------------------------------------------------


def animated_camera(eye: Callable[[float], Sequence[float]], target: Callable[[float], Sequence[float]],
                    duration_s: float, lens_mm: float = 30.0, key_every: int = 10) -> bpy.types.Object:
    """A camera keyed every `key_every` frames (Bezier in between) from closed-form eye/target paths of
    time in seconds. Frames run 1..duration*fps; Euler angles are kept continuous between keys."""
    scene = bpy.context.scene
    data = bpy.data.cameras.new("Camera")
    data.lens = lens_mm
    data.clip_start, data.clip_end = 0.05, 2000.0
    cam = add_object("Camera", data)
    scene.camera = cam
    n_frames = round(duration_s * FPS)
    scene.frame_start, scene.frame_end = 1, n_frames
    prev: Euler | None = None
    frames = [*range(1, n_frames + 1, key_every)]
    if frames[-1] != n_frames:
        frames.append(n_frames)
    for f in frames:
        t = (f - 1) / FPS
        e, g = Vector(eye(t)), Vector(target(t))
        quat = (g - e).to_track_quat("-Z", "Y")
        rot = quat.to_euler("XYZ", prev) if prev is not None else quat.to_euler("XYZ")
        prev = rot
        cam.location = e
        cam.rotation_euler = rot
        cam.keyframe_insert("location", frame=f)
        cam.keyframe_insert("rotation_euler", frame=f)
    return cam


def camera_clearance(cam: bpy.types.Object, every: int = 10) -> tuple[float, list[str]]:
    """Check a camera path against the scene: the smallest distance from the camera to any surface (rays
    in 26 directions) and the frames where the camera is inside a solid (most directions first hit a back
    face; a few back faces are normal where open surfaces or grazing rays are seen). Catches paths that clip
    through walls, terrain or objects."""
    scene = bpy.context.scene
    grid = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)]
    dirs = np.array([g for g in grid if g != (0, 0, 0)], dtype=np.float64)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    nearest, inside = math.inf, []
    nearest_at = ""
    for f in range(scene.frame_start, scene.frame_end + 1, every):
        scene.frame_set(f)
        deps = bpy.context.evaluated_depsgraph_get()
        origin = cam.matrix_world.translation.copy()
        hits = back = 0
        for d in dirs:
            hit, loc, normal, _i, obj, _m = scene.ray_cast(deps, origin, Vector(d))
            if not hit:
                continue
            dist = (loc - origin).length
            if dist < nearest:
                nearest, nearest_at = dist, f"frame {f}: {obj.name}"
            hits += 1
            if normal.dot(Vector(d)) > 0:
                back += 1
                last_back = f"{obj.name} at {dist:.2f} m"
        if hits and back >= max(3, hits // 2):
            inside.append(f"frame {f}: inside {last_back} ({back}/{hits} back faces)")
    scene.frame_set(scene.frame_start)
    clipping = bool(inside) or nearest < 0.3
    return nearest, ([*inside, f"nearest surface {nearest:.3f} m at {nearest_at}"] if clipping else [])


def export_scene_file(path: Path) -> dict:
    """The scene as the add-on sends it to jobs (and the render engine renders it): the depsgraph translator
    at render level, written as a render-budget scene file. Returns a summary for stats.json."""
    translation = translate_for_render(bpy.context.scene)
    scene_id = write_scene_file(path, translation.scene_data, translation.notes)
    data = translation.scene_data
    return {
        "scene_id": scene_id,
        "triangles": int(data.triangles.shape[0]),
        "instances": len(data.object_names),
        "unique_meshes": translation.stats["unique_meshes"],
        "light_kinds": sorted({lt.kind for lt in data.lights}),
        "environment": translation.stats["environment"],
        "notes": [str(n) for n in translation.notes],
    }


def smooth_path(points: Sequence[Sequence[float]], duration_s: float) -> Callable[[float], np.ndarray]:
    """Closed Catmull-Rom curve through `points`, parameterised uniformly over the duration."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)

    def at(t: float) -> np.ndarray:
        u = (t / duration_s) * n
        i = math.floor(u) % n
        s = u - math.floor(u)
        p0, p1, p2, p3 = pts[(i - 1) % n], pts[i], pts[(i + 1) % n], pts[(i + 2) % n]
        return 0.5 * ((2 * p1) + (-p0 + p2) * s + (2 * p0 - 5 * p1 + 4 * p2 - p3) * s * s
                      + (-p0 + 3 * p1 - 3 * p2 + p3) * s ** 3)

    return at
