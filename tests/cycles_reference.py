"""Cycles as the reference for light units and the world: small scenes rendered by Cycles and the simulator.

Light cases: a diffuse plane with a diffuse cube on it (so soft-shadow size matters), a black world and one
light made the Blender way (type, watts or W/m^2, radius / angle / shape / size, spot size and blend, an
object rotation and scale). Cycles renders it with ``diffuse_bounces = 0`` (the simulated GPU traces no
diffuse inter-reflection); the simulator gets the same light through ``Light.from_blender`` (what a
depsgraph translation does) and the same camera. Both images are linear; the check is their mean
brightness. World case: one of Blender's bundled HDRIs as an Environment Texture, with a strength and a
Mapping node's Z rotation, seen by a camera (no geometry). Shared by ``tests/test_cycles_reference.py``
(small, few samples) and ``bench/bench_light_units.py``.
"""

from __future__ import annotations

import math
import os
import tempfile
from typing import Any

import numpy as np
from sim_core.image import linear_to_srgb

from service.metrics import ssim

ALBEDO = 0.8
CAMERA_LOCATION = (0.0, -6.0, 4.5)
CAMERA_TARGET = (0.0, 0.5, 0.0)
CAMERA_FOV = math.radians(55.0)
PLANE_HALF = 30.0

#: Blender light data per case: type, energy and the light's own settings, plus the object's placement.
CASES: dict[str, dict[str, Any]] = {
    "point": dict(type="POINT", energy=1000.0, shadow_soft_size=0.0, location=(1.5, -1.0, 3.0)),
    "point_radius": dict(type="POINT", energy=600.0, shadow_soft_size=0.8, location=(1.2, -1.0, 2.2)),
    "spot": dict(type="SPOT", energy=1500.0, shadow_soft_size=0.0, spot_size=math.radians(50), spot_blend=0.0,
                 location=(0.0, -2.0, 4.0), rotation=(math.radians(25), 0.0, 0.0)),
    "spot_blend": dict(type="SPOT", energy=1500.0, shadow_soft_size=0.3, spot_size=math.radians(50),
                       spot_blend=0.7, location=(0.0, -2.0, 4.0), rotation=(math.radians(25), 0.0, 0.0)),
    "sun": dict(type="SUN", energy=3.0, angle=0.0, rotation=(math.radians(35), 0.0, math.radians(30))),
    "sun_angle": dict(type="SUN", energy=3.0, angle=math.radians(12), rotation=(math.radians(35), 0.0,
                                                                                 math.radians(30))),
    "area_square": dict(type="AREA", energy=400.0, shape="SQUARE", size=1.0, location=(0.8, -0.8, 2.5),
                        rotation=(math.radians(20), 0.0, math.radians(40))),
    "area_rectangle": dict(type="AREA", energy=500.0, shape="RECTANGLE", size=3.0, size_y=0.6,
                           location=(0.0, -1.0, 1.8), rotation=(math.radians(-15), math.radians(10), 0.4)),
    "area_disk": dict(type="AREA", energy=500.0, shape="DISK", size=2.0, location=(0.5, 0.0, 2.0)),
    "area_ellipse": dict(type="AREA", energy=500.0, shape="ELLIPSE", size=2.5, size_y=1.0,
                         location=(-0.5, -0.5, 1.6), rotation=(0.0, math.radians(20), 0.6),
                         scale=(1.3, 0.8, 1.0)),
}

_LIGHT_SETTINGS = ("shadow_soft_size", "spot_size", "spot_blend", "angle", "shape", "size", "size_y")


def _look_at_matrix(eye: tuple[float, float, float], target: tuple[float, float, float]) -> np.ndarray:
    """Blender camera world matrix looking from eye at target (local -Z forward, +Y up)."""
    e, t = np.asarray(eye, float), np.asarray(target, float)
    fwd = (t - e) / np.linalg.norm(t - e)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, -fwd, e
    return m


def _cube() -> tuple[np.ndarray, np.ndarray]:
    c = np.array([[x, y, z] for z in (0.0, 1.0) for y in (-0.5, 0.5) for x in (-0.5, 0.5)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    tris = [t for a, b, c2, d in quads for t in ((a, b, c2), (a, c2, d))]
    return c, np.asarray(tris)


def blender_light_matrix(case: dict[str, Any]) -> np.ndarray:
    """The light object's world matrix (XYZ Euler rotation, scale, location) as Blender composes it."""
    rx, ry, rz = case.get("rotation", (0.0, 0.0, 0.0))
    cx, sx, cy, sy = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry)
    cz, sz = math.cos(rz), math.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = rot_z @ rot_y @ rot_x @ np.diag(case.get("scale", (1.0, 1.0, 1.0)))
    m[:3, 3] = case.get("location", (0.0, 0.0, 5.0))
    return m


def _simulator_plane_and_cube(size: int, settings: Any, **scene_args: Any) -> tuple[float, np.ndarray]:
    """Mean linear brightness (and the image) of the diffuse plane and cube with ``scene_args`` (lights,
    environment), rendered by the simulator from the cases' camera."""
    from sim_core import Camera, Material, RenderSettings, Scene, render

    h = PLANE_HALF
    plane = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], float)
    cube_p, cube_t = _cube()
    pos = np.vstack([plane, cube_p])
    tri = np.vstack([[[0, 1, 2], [0, 2, 3]], cube_t + 4])
    # ior 1: no specular layer, like Cycles' Diffuse BSDF.
    diffuse = Material(base_color=(ALBEDO, ALBEDO, ALBEDO), roughness=1.0, ior=1.0)
    scene = Scene.from_arrays(pos, tri, materials=[diffuse], **scene_args)
    cam = Camera.from_blender(_look_at_matrix(CAMERA_LOCATION, CAMERA_TARGET), CAMERA_FOV, size, size)
    r = render(scene, cam, settings or RenderSettings.max_quality())
    return float(r.image.mean()), r.image


def simulator_mean(name: str, size: int = 48, settings: Any = None) -> tuple[float, np.ndarray]:
    """Mean linear brightness (and the image) of the case rendered by the simulator."""
    from sim_core import Light

    case = CASES[name]
    kwargs = {k: case[k] for k in _LIGHT_SETTINGS if k in case}
    light = Light.from_blender(case["type"], blender_light_matrix(case), case["energy"], **kwargs)
    return _simulator_plane_and_cube(size, settings, lights=[light], environment=(0.0, 0.0, 0.0))


def _cycles_scene(size_x: int, size_y: int, samples: int) -> Any:
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    sc = bpy.context.scene
    cycles_settings(sc, size_x, size_y, samples)
    return sc


def cycles_settings(sc: Any, size_x: int, size_y: int, samples: int, *, depth: int = 1,
                    denoise: bool = False) -> None:
    """Make ``sc`` render as the reference: Cycles on the CPU, ``diffuse_bounces = 0`` (the simulated GPU
    traces no diffuse inter-reflection), glossy and transmission bounces (and the total) = ``depth``, a
    fixed seed, the Standard view transform, no compositing."""
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = denoise
    if denoise:
        sc.cycles.denoiser = "OPENIMAGEDENOISE"
    sc.cycles.diffuse_bounces = 0
    sc.cycles.glossy_bounces = sc.cycles.transmission_bounces = depth
    sc.cycles.max_bounces = depth
    sc.cycles.seed = 1
    sc.render.resolution_x, sc.render.resolution_y = size_x, size_y
    sc.render.resolution_percentage = 100
    sc.render.use_compositing = sc.render.use_sequencer = False
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0


def cycles_render(sc: Any) -> np.ndarray:
    """Render the scene to a float EXR and read it back (linear RGB, row 0 at the top)."""
    import bpy
    import OpenEXR

    with tempfile.TemporaryDirectory(prefix="cycles-reference-") as folder:
        path = os.path.join(folder, "render.exr")
        sc.render.image_settings.file_format = "OPEN_EXR"
        sc.render.image_settings.color_depth = "32"
        sc.render.filepath = path
        bpy.ops.render.render(write_still=True)
        with OpenEXR.File(path) as f:
            channels = f.channels()
            key = "RGBA" if "RGBA" in channels else "RGB"
            return np.asarray(channels[key].pixels, dtype=np.float64)[..., :3]


def _camera(sc: Any, matrix: np.ndarray, angle: float) -> None:
    import bpy
    from mathutils import Matrix

    cam_data = bpy.data.cameras.new("camera")
    cam_data.angle = angle
    cam = bpy.data.objects.new("camera", cam_data)
    sc.collection.objects.link(cam)
    cam.matrix_world = Matrix(matrix.tolist())
    sc.camera = cam


def _cycles_plane_and_cube(sc: Any) -> None:
    """The diffuse plane and cube (Diffuse BSDF) and the cases' camera in ``sc``."""
    import bpy

    mat = bpy.data.materials.new("diffuse")
    if mat.node_tree is None:  # Blender < 5 makes the node tree on request
        mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (ALBEDO, ALBEDO, ALBEDO, 1.0)
    mat.node_tree.links.new(bsdf.outputs[0], out.inputs[0])
    cube_p, cube_t = _cube()
    plane = [(-PLANE_HALF, -PLANE_HALF, 0), (PLANE_HALF, -PLANE_HALF, 0), (PLANE_HALF, PLANE_HALF, 0),
             (-PLANE_HALF, PLANE_HALF, 0)]
    for mesh_name, verts, faces in (("plane", plane, [(0, 1, 2, 3)]),
                                    ("cube", [tuple(v) for v in cube_p], [tuple(t) for t in cube_t])):
        mesh = bpy.data.meshes.new(mesh_name)
        mesh.from_pydata(verts, [], faces)
        mesh.materials.append(mat)
        sc.collection.objects.link(bpy.data.objects.new(mesh_name, mesh))
    _camera(sc, _look_at_matrix(CAMERA_LOCATION, CAMERA_TARGET), CAMERA_FOV)


def cycles_mean(name: str, size: int = 48, samples: int = 64) -> tuple[float, np.ndarray]:
    """Mean linear brightness (and the image) of the case rendered by Cycles (CPU, bpy module)."""
    import bpy

    case = CASES[name]
    sc = _cycles_scene(size, size, samples)
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is None:  # Blender < 5 makes the node tree on request
        world.use_nodes = True
    for node in world.node_tree.nodes:  # a new world's Background node is grey: make it black
        if node.type == "BACKGROUND":
            node.inputs["Strength"].default_value = 0.0
    sc.world = world
    _cycles_plane_and_cube(sc)
    light_data = bpy.data.lights.new("light", case["type"])
    light_data.energy = case["energy"]
    for key in _LIGHT_SETTINGS:
        if key in case and hasattr(light_data, key):
            setattr(light_data, key, case[key])
    light = bpy.data.objects.new("light", light_data)
    sc.collection.objects.link(light)
    light.location = case.get("location", (0.0, 0.0, 5.0))
    light.rotation_euler = case.get("rotation", (0.0, 0.0, 0.0))
    light.scale = case.get("scale", (1.0, 1.0, 1.0))
    bpy.context.view_layer.update()
    # The matrix the simulator uses must be Blender's own.
    assert np.allclose(np.array(light.matrix_world), blender_light_matrix(case), atol=1e-5)
    image = cycles_render(sc)
    return float(image.mean()), image


# ---- the world: an HDRI with strength and rotation ----------------------------------------------------

WORLD_HDRI = "forest.exr"  # one of Blender's bundled studio-light HDRIs (it holds negative texels)
WORLD_VIEW = ((0.0, 0.0, 0.0), (1.0, 0.6, 0.3))  # camera at the origin looking up and to the side
WORLD_FOV = math.radians(70.0)  # Blender's camera angle: the horizontal field of view of a wide image


def bundled_hdri(name: str = WORLD_HDRI) -> str:
    import bpy

    return os.path.join(bpy.utils.system_resource("DATAFILES"), "studiolights", "world", name)


def cycles_world(strength: float, rotation_z: float, size: tuple[int, int] = (64, 32),
                 samples: int = 16) -> np.ndarray:
    """Cycles' background: Environment Texture (Generated coordinates through a Mapping node's Z rotation)
    times ``strength``, seen by a camera at WORLD_VIEW."""
    sc = _cycles_scene(size[0], size[1], samples)
    sc.world = _hdri_world(strength, rotation_z)
    _camera(sc, _look_at_matrix(*WORLD_VIEW), WORLD_FOV)
    return cycles_render(sc)


def _hdri_world(strength: float, rotation_z: float) -> Any:
    """A World: the bundled HDRI as an Environment Texture (Generated coordinates through a Mapping node's
    Z rotation) times ``strength``."""
    import bpy

    world = bpy.data.worlds.new("hdri")
    if world.node_tree is None:
        world.use_nodes = True
    tree = world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(bundled_hdri())
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
    coords = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    background = next(n for n in tree.nodes if n.type == "BACKGROUND")
    tree.links.new(env.outputs["Color"], background.inputs["Color"])
    background.inputs["Strength"].default_value = strength
    return world


def _bundled_map() -> np.ndarray:
    """The HDRI as the simulator reads it (load_exr clamps its negative texels)."""
    import warnings

    import sim_core

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sim_core.load_exr(bundled_hdri())


def cycles_world_lit(strength: float, rotation_z: float, size: int = 48,
                     samples: int = 64) -> tuple[float, np.ndarray]:
    """Mean linear brightness (and the image) of the diffuse plane and cube lit by the HDRI world alone
    (its sky and its sun, the cube's shadow), rendered by Cycles."""
    sc = _cycles_scene(size, size, samples)
    sc.world = _hdri_world(strength, rotation_z)
    _cycles_plane_and_cube(sc)
    image = cycles_render(sc)
    return float(image.mean()), image


def simulator_world_lit(strength: float, rotation_z: float, size: int = 48,
                        settings: Any = None) -> tuple[float, np.ndarray]:
    """The same, rendered by the simulator (the map's sun as an environment light, the rest as ambient
    light occluded by AO rays)."""
    return _simulator_plane_and_cube(size, settings, environment=_bundled_map(),
                                     environment_strength=strength, environment_rotation=rotation_z)


def simulator_world(strength: float, rotation_z: float, size: tuple[int, int] = (64, 32)) -> np.ndarray:
    """The simulator's view of the same world (the HDRI through load_exr, which clamps negative texels)."""
    from sim_core import Camera, RenderSettings, Scene, render

    env = _bundled_map()
    far = np.array([[0, 0, -1e3], [1e-3, 0, -1e3], [0, 1e-3, -1e3]], np.float32)  # out of view
    scene = Scene.from_arrays(far, np.array([[0, 1, 2]]), environment=env, environment_strength=strength,
                              environment_rotation=rotation_z)
    w, h = size
    vfov = 2 * math.atan(math.tan(WORLD_FOV / 2) * h / w)
    cam = Camera.from_blender(_look_at_matrix(*WORLD_VIEW), vfov, w, h)
    return render(scene, cam, RenderSettings(mode="fsaa", block=4)).image


# ---- an artist's scene: textured cube, glossy sphere, rough metal floor, three lights, HDRI --------------

# An 8x8-cell yellow / green checker: sRGB bytes, row 0 at the top.
CHECKER = (((np.arange(64)[:, None] // 8 + np.arange(64)[None, :] // 8) % 2)[..., None]
           * np.array([205, 110, 0]) + np.array([25, 60, 25])).astype(np.uint8)
ARTIST_LIGHTS: dict[str, dict[str, Any]] = {
    "area": dict(type="AREA", energy=300.0, shape="RECTANGLE", size=2.0, size_y=1.0,
                 location=(2.5, -2.0, 3.5), rotation=(0.7, 0.0, 0.9)),
    "point": dict(type="POINT", energy=200.0, shadow_soft_size=0.3, location=(-2.5, -1.5, 2.5)),
    "sun": dict(type="SUN", energy=1.5, angle=math.radians(5), location=(0.0, 0.0, 5.0),
                rotation=(0.6, 0.2, 2.0)),
}
ARTIST_CAMERA = dict(location=(0.0, -6.5, 2.6), rotation=(math.radians(72), 0.0, 0.0), lens=35.0)
ARTIST_WORLD_STRENGTH = 0.8


def _uv_box(size: float, centre: tuple[float, float, float], yaw: float) -> tuple:
    """A cube as 6 quads with 0..1 UVs per face: (positions (24,3), quads (6,4), uvs (24,2), normals)."""
    h = size / 2
    faces = [((0, 0, 1), (1, 0, 0)), ((0, 0, -1), (1, 0, 0)), ((1, 0, 0), (0, 1, 0)),
             ((-1, 0, 0), (0, -1, 0)), ((0, 1, 0), (-1, 0, 0)), ((0, -1, 0), (1, 0, 0))]
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    pos, uv, nrm, quads = [], [], [], []
    for n, t in faces:
        n, t = np.asarray(n, float), np.asarray(t, float)
        b = np.cross(n, t)
        base = len(pos)
        for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
            pos.append(rot @ (n * h + t * (du - 0.5) * size + b * (dv - 0.5) * size) + centre)
            uv.append((du, dv))
            nrm.append(rot @ n)
        quads.append((base, base + 1, base + 2, base + 3))
    return np.asarray(pos), np.asarray(quads), np.asarray(uv, float), np.asarray(nrm)


def _uv_sphere(radius: float, centre: tuple[float, float, float], nu: int = 48, nv: int = 24) -> tuple:
    """A UV sphere as quads (poles as degenerate quads) with smooth normals and UVs."""
    pos, uv, nrm = [], [], []
    for j in range(nv + 1):
        th = math.pi * j / nv
        for i in range(nu + 1):
            ph = 2 * math.pi * i / nu
            n = np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])
            pos.append(np.asarray(centre) + radius * n)
            nrm.append(n)
            uv.append((i / nu, 1 - j / nv))
    quads = [(j * (nu + 1) + i, (j + 1) * (nu + 1) + i, (j + 1) * (nu + 1) + i + 1, j * (nu + 1) + i + 1)
             for j in range(nv) for i in range(nu)]
    return np.asarray(pos), np.asarray(quads), np.asarray(uv, float), np.asarray(nrm)


def _artist_meshes() -> list[tuple[str, tuple, dict[str, Any]]]:
    h = 6.0
    floor = (np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], float), np.array([[0, 1, 2, 3]]),
             np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float), np.tile([0.0, 0.0, 1.0], (4, 1)))
    return [
        ("floor", floor, dict(base=(0.8, 0.8, 0.8), metallic=1.0, roughness=0.45)),
        ("cube", _uv_box(1.5, (-1.2, 0.5, 0.75), 0.5),
         dict(base=(1.0, 1.0, 1.0), roughness=0.5, texture=True)),
        ("sphere", _uv_sphere(0.8, (1.3, 0.2, 0.8)), dict(base=(0.1, 0.2, 0.8), roughness=0.3)),
    ]


def _artist_camera_matrix() -> np.ndarray:
    case = dict(rotation=ARTIST_CAMERA["rotation"], location=ARTIST_CAMERA["location"])
    return blender_light_matrix(case)  # the same Euler composition as any Blender object


def _artist_vfov(width: int, height: int) -> float:
    hfov = 2 * math.atan(36.0 / 2 / ARTIST_CAMERA["lens"])  # Blender's 36 mm sensor, fit to the width
    return 2 * math.atan(math.tan(hfov / 2) * height / width)


def cycles_artist(size: tuple[int, int] = (320, 180), samples: int = 128, denoise: bool = True) -> np.ndarray:
    """Cycles' render of the artist scene (glossy and transmission bounces 3, diffuse bounces 0)."""
    import bpy

    sc = _cycles_scene(size[0], size[1], samples)
    sc.cycles.use_denoising = denoise
    sc.cycles.glossy_bounces = sc.cycles.transmission_bounces = 3
    sc.cycles.max_bounces = 4
    image = bpy.data.images.new("checker", CHECKER.shape[1], CHECKER.shape[0])
    rgba = np.concatenate([CHECKER, np.full((*CHECKER.shape[:2], 1), 255, np.uint8)], axis=2)
    image.pixels.foreach_set((rgba[::-1].astype(np.float32) / 255.0).ravel())  # Blender's rows run upwards
    image.pack()
    for name, (pos, quads, uv, _normals), m in _artist_meshes():
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata([tuple(p) for p in pos], [], [tuple(q) for q in quads])
        layer = mesh.uv_layers.new()
        for loop in mesh.loops:
            layer.data[loop.index].uv = tuple(uv[loop.vertex_index])
        if name == "sphere":
            for poly in mesh.polygons:
                poly.use_smooth = True
        mat = bpy.data.materials.new(name)
        if mat.node_tree is None:
            mat.use_nodes = True
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (*m["base"], 1.0)
        bsdf.inputs["Metallic"].default_value = m.get("metallic", 0.0)
        bsdf.inputs["Roughness"].default_value = m["roughness"]
        if m.get("texture"):
            tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
            tex.image = image
            mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
        mesh.materials.append(mat)
        sc.collection.objects.link(bpy.data.objects.new(name, mesh))
    for name, case in ARTIST_LIGHTS.items():
        data = bpy.data.lights.new(name, case["type"])
        data.energy = case["energy"]
        for key in _LIGHT_SETTINGS:
            if key in case:
                setattr(data, key, case[key])
        obj = bpy.data.objects.new(name, data)
        sc.collection.objects.link(obj)
        obj.location = case.get("location", (0.0, 0.0, 5.0))
        obj.rotation_euler = case.get("rotation", (0.0, 0.0, 0.0))
    sc.world = _hdri_world(ARTIST_WORLD_STRENGTH, 0.0)
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = ARTIST_CAMERA["lens"]
    cam = bpy.data.objects.new("camera", cam_data)
    sc.collection.objects.link(cam)
    cam.location = ARTIST_CAMERA["location"]
    cam.rotation_euler = ARTIST_CAMERA["rotation"]
    sc.camera = cam
    bpy.context.view_layer.update()
    assert np.allclose(np.array(cam.matrix_world), _artist_camera_matrix(), atol=1e-5)
    return cycles_render(sc)


def simulator_artist(size: tuple[int, int] = (320, 180), settings: Any = None) -> Any:
    """The simulator's render (a RenderResult) of the same scene, built from the same description."""
    from sim_core import Camera, Light, Material, RenderSettings, Scene, Texture, render

    pos, tri, uvs, nrm, mids = [], [], [], [], []
    materials = []
    base = 0
    for index, (_name, (p, quads, uv, normals), m) in enumerate(_artist_meshes()):
        tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        pos.append(p)
        uvs.append(uv)
        nrm.append(normals)
        tri.append(tris + base)
        mids.append(np.full(len(tris), index))
        base += len(p)
        texture = 0 if m.get("texture") else None
        materials.append(Material(base_color=m["base"], metallic=m.get("metallic", 0.0),
                                  roughness=m["roughness"], base_color_texture=texture))
    lights = []
    for name, case in ARTIST_LIGHTS.items():
        kwargs = {k: case[k] for k in _LIGHT_SETTINGS if k in case}
        lights.append(Light.from_blender(case["type"], blender_light_matrix(case), case["energy"], name=name,
                                         **kwargs))
    env = _bundled_map()
    mid = np.concatenate(mids)
    scene = Scene.from_arrays(np.vstack(pos), np.vstack(tri), normals=np.vstack(nrm), uvs=np.vstack(uvs),
                              textures=[Texture(CHECKER, name="checker")], materials=materials,
                              material_ids=mid, object_ids=mid, lights=lights, environment=env,
                              environment_strength=ARTIST_WORLD_STRENGTH)
    w, h = size
    cam = Camera.from_blender(_artist_camera_matrix(), _artist_vfov(w, h), w, h)
    return render(scene, cam, settings or RenderSettings.max_quality())


def display_luminance(linear: np.ndarray) -> float:
    """Mean Rec. 709 luma of the display image (the project's display transform, Blender's Standard view)."""
    return float((linear_to_srgb(linear) @ np.array([0.2126, 0.7152, 0.0722])).mean())


def fidelity(cycles: np.ndarray, simulated: np.ndarray) -> tuple[float, float]:
    """(mean display luminance ratio simulated / Cycles, 1 - SSIM of the display images), through the
    project's error pipeline (``sim_core.image.linear_to_srgb``, ``service.metrics.ssim``)."""
    ratio = display_luminance(simulated) / display_luminance(cycles)
    return ratio, 1.0 - ssim(linear_to_srgb(cycles), linear_to_srgb(simulated), data_range=1.0)
