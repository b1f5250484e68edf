"""The artist's scene: what a Blender user builds in a few minutes and expects the simulated GPU to render
as Cycles does. A checker-textured cube (an Image Texture through UVs), a glass sphere with a Subdivision
Surface modifier (viewport level 1, render level 3) and a linked duplicate of it, a rough metal floor
(metallic 1, roughness 0.45), a collection excluded from the view layer and instanced twice, point + area +
sun lights, one of Blender's bundled HDRIs (forest.exr, turned by a Mapping node) as the world, and a
keyframed camera. Every feature the depsgraph translator carries is in it (seed: issue 12's test scene).
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import bmesh
import bpy
import numpy as np
from mathutils import Vector

from .. import common as c

DURATION_S = 30.0
HDRI = "forest.exr"
CHECKER_SIZE = 256
CHECKER_SQUARES = 8


def bundled_hdri(name: str = HDRI) -> Path:
    """One of the world HDRIs Blender ships (studio lights), whichever Blender builds the scene."""
    path = Path(bpy.utils.system_resource("DATAFILES")) / "studiolights" / "world" / name
    if not path.is_file():
        raise FileNotFoundError(f"Blender's bundled HDRI {name} is missing from {path.parent}")
    return path


def checker_image() -> bpy.types.Image:
    """An 8x8 checker (sRGB bytes, packed into the .blend): white and a deep blue."""
    n = CHECKER_SIZE
    cell = (np.arange(n) * CHECKER_SQUARES // n)
    odd = (cell[:, None] + cell[None, :]) % 2 == 1
    px = np.empty((n, n, 4), np.float32)
    px[...] = (0.92, 0.92, 0.92, 1.0)
    px[odd] = (0.08, 0.18, 0.55, 1.0)
    img = bpy.data.images.new("Checker", n, n, alpha=False)
    img.pixels.foreach_set(px.reshape(-1))
    img.pack()
    return img


def textured(name: str, image: bpy.types.Image, roughness: float = 0.4) -> bpy.types.Material:
    mat = c.principled(name, (1.0, 1.0, 1.0), roughness=roughness)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Linear"
    links.new(tex.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    mat.diffuse_color = (0.5, 0.55, 0.74, 1.0)
    return mat


def bm_mesh(name: str, fill, smooth: bool = False) -> bpy.types.Mesh:
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    fill(bm)
    for f in bm.faces:
        f.smooth = smooth
    bm.to_mesh(me)
    bm.free()
    return me


def build(out_dir: Path) -> c.SceneSpec:
    c.reset()
    scene = bpy.context.scene

    floor_mat = c.principled("RoughMetal", (0.8, 0.8, 0.82), metallic=1.0, roughness=0.45)
    glass = c.principled("Glass", (1.0, 1.0, 1.0), roughness=0.0, transmission=1.0, ior=1.45)
    clay = c.principled("Clay", (0.8, 0.35, 0.12), roughness=0.6)
    checker = textured("Checker", checker_image())

    c.add_object("Floor", c.box_mesh("Floor", (12.0, 12.0, 0.1), floor_mat), (0.0, 0.0, -0.05))

    def uv_cube(bm: bmesh.types.BMesh) -> None:
        bm.loops.layers.uv.new("UVMap")  # calc_uvs fills an existing UV map
        bmesh.ops.create_cube(bm, size=1.2, calc_uvs=True)

    cube_mesh = bm_mesh("CheckerCube", uv_cube)
    cube_mesh.materials.append(checker)
    c.add_object("CheckerCube", cube_mesh, (-1.6, 0.4, 0.6), (0.0, 0.0, math.radians(20)))

    sphere_mesh = c.uv_sphere_mesh("GlassSphere", segments=16, rings=8, radius=0.6, material=glass,
                                   smooth=True)
    for name, location in (("GlassSphere", (0.9, -0.6, 0.6)), ("GlassSphere.Linked", (2.3, 1.4, 0.6))):
        sphere = c.add_object(name, sphere_mesh, location)  # the second shares the mesh: Alt+D
        sub = sphere.modifiers.new("Subdivision", "SUBSURF")
        sub.levels, sub.render_levels = 1, 3

    # A collection kept out of the view layer and placed twice through collection instances.
    props = bpy.data.collections.new("Props")
    scene.collection.children.link(props)
    cone = bm_mesh("Cone", lambda bm: bmesh.ops.create_cone(
        bm, cap_ends=True, segments=24, radius1=0.35, radius2=0.0, depth=1.0), smooth=False)
    cone.materials.append(clay)
    c.add_object("Cone", cone, (0.0, 0.0, 0.6), collection=props)
    plinth = c.box_mesh("Plinth", (0.8, 0.8, 0.1), clay)
    c.add_object("Plinth", plinth, (0.0, 0.0, 0.05), collection=props)
    bpy.context.view_layer.layer_collection.children["Props"].exclude = True
    for name, location, turn in (("PropsA", (-2.6, -1.9, 0.0), 15.0), ("PropsB", (2.9, -1.6, 0.0), -30.0)):
        empty = c.add_object(name, None, location, (0.0, 0.0, math.radians(turn)))
        empty.instance_type = "COLLECTION"
        empty.instance_collection = props

    c.point_light("PointLight", (-2.5, -3.0, 4.0), watts=600.0, radius=0.25)
    area = bpy.data.lights.new("AreaLight", "AREA")
    area.shape, area.size, area.size_y, area.energy = "RECTANGLE", 2.0, 1.0, 400.0
    area_location = Vector((2.5, 2.5, 3.5))
    rot = (Vector((0.0, 0.0, 0.5)) - area_location).to_track_quat("-Z", "Y").to_euler()
    c.add_object("AreaLight", area, area_location, rot)
    c.sun_light("Sun", (0.4, 0.6, -0.7), strength=2.0, angle_deg=3.0)

    # World: Blender's bundled forest HDRI, turned 40 degrees about Z by a Mapping node (as artists do).
    env_path = out_dir / "environment.exr"
    shutil.copyfile(bundled_hdri(), env_path)
    os.chmod(env_path, 0o644)
    c.world_exr(env_path, rotation_z=math.radians(40.0)).pack()  # the .blend carries its world
    def eye(t: float) -> np.ndarray:  # a half orbit, rising slowly
        a = -math.pi / 2 - 0.6 + math.pi * t / DURATION_S
        r = 6.4 + 0.5 * math.sin(2 * math.pi * t / DURATION_S)
        return np.array([r * math.cos(a), r * math.sin(a), 2.2 + 0.6 * t / DURATION_S])

    cam = c.animated_camera(eye, lambda t: (0.2, 0.0, 0.6), DURATION_S, lens_mm=30.0)
    return c.SceneSpec("artist", "The artist's scene: checker-textured cube, subdivided glass spheres (one a "
                       "linked duplicate), rough metal floor, an excluded collection instanced twice, point, "
                       "area and sun lights, Blender's forest HDRI", cam, DURATION_S, extra_files=[env_path])
