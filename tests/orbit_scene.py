"""A lit box on a floor with a camera orbiting it (keyframed, 24 fps), built with bpy alone, and the
options of a job on it that takes seconds.

Imports nothing of this project: the extension's end-to-end test copies this file next to its script in
a virtual environment that holds only bpy, and the add-on tests in this project's environment use it too.
"""

from __future__ import annotations

import math
from typing import Any


def build(bpy: Any, frames: int = 16, resolution: tuple[int, int] = (96, 54)) -> Any:
    """A fresh empty file holding the scene; returns the scene."""
    import bmesh

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = *resolution, 100
    sc.render.fps, sc.render.fps_base = 24, 1.0
    for name, size, loc in (("Box", 1.0, (0, 0, 0.5)), ("Floor", 6.0, (0, 0, -3.0))):
        me = bpy.data.meshes.new(name)
        bm = bmesh.new()
        bmesh.ops.create_cube(bm, size=size)
        bm.to_mesh(me)
        bm.free()
        ob = bpy.data.objects.new(name, me)
        ob.location = loc
        sc.collection.objects.link(ob)
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    light.data.energy = 800
    light.location = (2, -2, 3)
    sc.collection.objects.link(light)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.data.lens = 30
    sc.collection.objects.link(cam)
    sc.camera = cam
    sc.frame_start, sc.frame_end = 1, frames
    for i in range(frames):
        a = 2 * math.pi * i / frames
        cam.location = (4 * math.cos(a), 4 * math.sin(a), 1.2)
        cam.rotation_euler = (math.radians(80), 0.0, a + math.pi / 2)
        cam.keyframe_insert("location", frame=i + 1)
        cam.keyframe_insert("rotation_euler", frame=i + 1)
    return sc


JOB_PARAMETERS = ("sampling", "shadow_samples", "resolution_scale")


def small_job(props: Any) -> None:
    """Options of a job that takes seconds (on the add-on's scene settings): 3 searched parameters,
    octree depth 0, a small population, tiny evaluation images."""
    for name in JOB_PARAMETERS:
        props.parameters.add().name = name
    props.eval_width, props.eval_height = 32, 18
    props.max_depth, props.population, props.generations, props.exhaustive_limit = 0, 8, 2, 128
    props.filter_period = 0.25
