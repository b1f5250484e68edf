"""Village: a Provence-like hill village (>= 600K triangles) of instanced houses, trees, lamps and a
church around a square with a fountain (seed: the power-budget paper's large outdoor scene)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from .. import common as c

DURATION_S = 60.0
SIZE = 300.0
GRID = 300  # 2 * 299^2 = 178,802 ground triangles


def ground_height(x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
    """A gentle hill with the village on its shoulder (closed form: houses and camera sit on it)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    return (12.0 * np.exp(-((x - 40.0) ** 2 + (y - 30.0) ** 2) / (2 * 70.0**2))
            + 1.5 * np.sin(x / 23.0) * np.cos(y / 31.0) + 0.6 * np.sin(x / 7.0 + y / 11.0))


_BOX_F = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float], slot: int) -> tuple:
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=np.float64)
    return v, _BOX_F.copy(), slot


def house_mesh(name: str, w: float, d: float, h: float, mats: list[bpy.types.Material]) -> bpy.types.Mesh:
    """Walls, windows and door (inset boxes), a gable roof of overlapping tile rows, a chimney.
    Slots: 0 wall, 1 roof, 2 window glass, 3 wood."""
    parts = [_box((-w / 2, -d / 2, 0.0), (w / 2, d / 2, h), 0)]
    floors = max(1, round(h / 3.0))
    for fl in range(floors):
        z0 = 0.9 + fl * 3.0
        for k in range(max(1, round(w / 2.5))):
            x = -w / 2 + (k + 0.5) * w / max(1, round(w / 2.5))
            for side in (-1, 1):
                y = side * d / 2
                parts.append(_box((x - 0.45, y - 0.06, z0), (x + 0.45, y + 0.06, z0 + 1.2), 2))
                parts.append(_box((x - 0.6, y - 0.09, z0 - 0.1), (x + 0.6, y + 0.09, z0), 3))  # sill
    parts.append(_box((-0.55, -d / 2 - 0.08, 0.0), (0.55, -d / 2 + 0.02, 2.1), 3))  # door
    pitch = math.radians(32.0)
    half = d / 2 + 0.4
    rise = math.tan(pitch) * half
    rows = 10
    for side in (-1, 1):
        for r in range(rows):
            y0 = -half + r * half / rows
            y1 = y0 + half / rows + 0.08
            z0 = h + (y0 + half) * math.tan(pitch)
            # Stepped rows of tiles from the eave (z = h) up to the ridge.
            v, f, s = _box((-w / 2 - 0.3, y0, z0 - 0.06), (w / 2 + 0.3, y1, z0 + 0.04), 1)
            if side == 1:
                v[:, 1] = -v[:, 1]
                f = f[:, ::-1]
            parts.append((v, f, s))
    parts.append(_box((w / 4 - 0.4, -0.4, h), (w / 4 + 0.4, 0.4, h + rise + 1.0), 0))  # chimney
    # Gable ends: one outward-facing triangle each, up to the ridge.
    for x in (-w / 2, w / 2):
        v = np.array([[x, -d / 2, h], [x, d / 2, h], [x, 0.0, h + rise - 0.2]])
        parts.append((v, np.array([[0, 1, 2]]) if x > 0 else np.array([[1, 0, 2]]), 0))
    verts, faces_list, slots = [], [], []
    base = 0
    for v, f, s in parts:
        verts.append(v)
        faces_list.extend([tuple(int(i) + base for i in face) for face in f])
        slots.extend([s] * len(f))
        base += len(v)
    return c.mesh_from_arrays(name, np.concatenate(verts), faces_list, mats, material_indices=np.array(slots))


def tree_mesh(name: str, mats: list[bpy.types.Material], height: float, crowns: int) -> bpy.types.Mesh:
    """A trunk (lathe) and overlapping ico-sphere crowns: slots 0 bark, 1 leaves."""
    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=0.25, depth=height * 0.6,
                                        location=(0, 0, height * 0.3))
    trunk = bpy.context.active_object
    objs = [trunk]
    for k in range(crowns):
        a = 2 * math.pi * k / crowns
        r = 1.0 if crowns > 1 else 0.0
        at = (r * math.cos(a), r * math.sin(a), height * (0.65 + 0.1 * k))
        bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=4, radius=height * 0.28, location=at)  # 1280 tris
        crown = bpy.context.active_object
        objs.append(crown)
    for o in objs:
        o.data.materials.clear()
        o.data.materials.append(mats[0] if o is trunk else mats[1])
    with bpy.context.temp_override(active_object=trunk, selected_editable_objects=objs):
        bpy.ops.object.join()
    mesh = trunk.data
    mesh.name = name
    trunk.matrix_world.identity()
    for poly in mesh.polygons:
        poly.use_smooth = poly.material_index == 1
    bpy.data.objects.remove(trunk)
    return mesh


@dataclass(frozen=True)
class _Materials:
    grass: bpy.types.Material
    paving: bpy.types.Material
    walls: list[bpy.types.Material]
    roof: bpy.types.Material
    window: bpy.types.Material
    wood: bpy.types.Material
    bark: bpy.types.Material
    leaves: list[bpy.types.Material]
    stone: bpy.types.Material
    water: bpy.types.Material
    lamp_glow: bpy.types.Material
    iron: bpy.types.Material


def build(out_dir: Path) -> c.SceneSpec:
    """The scene in the order it always was built (object order and the random draws fix its content)."""
    c.reset()
    mats = _materials()
    xs = np.linspace(-SIZE / 2, SIZE / 2, GRID)
    gx, gy = np.meshgrid(xs, xs)
    c.add_object("Ground", c.grid_mesh("Ground", ground_height(gx, gy), SIZE, SIZE, mats.grass))
    sq_z = float(ground_height(0.0, 0.0))
    c.box("Square", (30.0, 30.0, 0.6), (0.0, 0.0, sq_z - 0.2), mats.paving)

    path_eye = c.smooth_path([(-120.0, -110.0, 45.0), (-40.0, -90.0, 30.0), (30.0, -50.0, 18.0),
                              (22.0, -12.0, sq_z + 6.0), (-8.0, -16.0, sq_z + 3.5), (-20.0, 8.0, sq_z + 5.0),
                              (28.0, 8.0, sq_z + 16.0), (70.0, 40.0, 30.0), (60.0, -60.0, 40.0)], DURATION_S)
    path_target = c.smooth_path([(0.0, 0.0, 5.0), (0.0, 0.0, 5.0), (0.0, 0.0, sq_z + 2.0),
                                 (0.0, 0.0, sq_z + 2.0), (0.0, 20.0, sq_z + 6.0), (10.0, 30.0, sq_z + 8.0),
                                 (-30.0, -20.0, 5.0), (-20.0, -10.0, 5.0), (0.0, 0.0, 5.0)], DURATION_S)
    # Keep the flight corridor clear: nothing tall within a few metres of where the camera flies low.
    corridor = np.array([path_eye(t) for t in np.linspace(0.0, DURATION_S, 1200)])

    def blocks_path(x: float, y: float, top: float, margin: float) -> bool:
        near = np.hypot(corridor[:, 0] - x, corridor[:, 1] - y) < margin
        return bool(np.any(near & (corridor[:, 2] < top + 2.0)))

    rng = np.random.default_rng(1789)
    n_houses = _houses(rng, mats, blocks_path)
    _trees(rng, mats, blocks_path)
    _church_and_fountain(mats, sq_z)
    _street_lamps(mats, sq_z)
    c.sun_light("Sun", (0.45, -0.5, -0.55), strength=3.0, angle_deg=0.8)
    c.world_color((0.55, 0.68, 0.88))

    cam = c.animated_camera(path_eye, path_target, DURATION_S, lens_mm=28.0)
    desc = f"Hill village: {n_houses} instanced houses, trees, church, fountain, lamps"
    return c.SceneSpec("village", desc, cam, DURATION_S)


def _materials() -> _Materials:
    """Every material, created in a fixed order (their order is part of the scene)."""
    grass = c.principled("Meadow", (0.35, 0.42, 0.18), roughness=0.9)
    paving = c.principled("Paving", (0.6, 0.55, 0.48), roughness=0.6)
    walls = [c.principled(f"Plaster{i}", col, roughness=0.85) for i, col in
             enumerate([(0.9, 0.8, 0.62), (0.85, 0.7, 0.55), (0.92, 0.88, 0.8), (0.8, 0.6, 0.45)])]
    roof = c.principled("RoofTiles", (0.62, 0.28, 0.16), roughness=0.7)
    window = c.principled("WindowGlass", (0.2, 0.25, 0.3), metallic=0.9, roughness=0.05)
    wood = c.principled("Shutters", (0.25, 0.4, 0.45), roughness=0.6)
    bark = c.principled("Bark", (0.25, 0.18, 0.12), roughness=0.9)
    leaves = [c.principled("Olive", (0.3, 0.38, 0.2), roughness=0.8),
              c.principled("Cypress", (0.12, 0.25, 0.1), roughness=0.8)]
    stone = c.principled("Stone", (0.7, 0.66, 0.58), roughness=0.75)
    water = c.principled("FountainWater", (0.6, 0.7, 0.75), roughness=0.02, transmission=1.0, ior=1.33)
    lamp_glow = c.principled("LampGlass", (1.0, 0.9, 0.7), emission=(1.0, 0.8, 0.5), emission_strength=5.0)
    iron = c.principled("Iron", (0.1, 0.1, 0.1), metallic=1.0, roughness=0.45)
    return _Materials(grass, paving, walls, roof, window, wood, bark, leaves, stone, water, lamp_glow, iron)


def _houses(rng: np.random.Generator, mats: _Materials, blocks_path: Callable[..., bool]) -> int:
    """Houses along a loose street grid around the square (skipping the square itself); returns how many."""
    variants = []
    for i, (w, d, h) in enumerate([(8, 6, 6), (10, 7, 9), (6, 6, 6), (12, 8, 9), (7, 5, 3), (9, 9, 6)]):
        slots = [mats.walls[i % 4], mats.roof, mats.window, mats.wood]
        variants.append(house_mesh(f"House{i}", w, d, h, slots))
    n_houses = 0
    for gxi in range(-7, 8):
        for gyi in range(-7, 8):
            if max(abs(gxi), abs(gyi)) <= 1 or rng.random() < 0.25:
                continue
            x = gxi * 16.0 + float(rng.normal(0, 2.0))
            y = gyi * 16.0 + float(rng.normal(0, 2.0))
            z = float(ground_height(x, y)) - 0.3
            if blocks_path(x, y, z + 16.0, 10.0):
                continue
            turn = (math.pi / 2) * int(rng.integers(0, 4)) + float(rng.normal(0, 0.05))
            variant = variants[int(rng.integers(0, len(variants)))]
            c.add_object(f"House{n_houses}", variant, (x, y, z), (0, 0, turn))
            n_houses += 1
    return n_houses


def _trees(rng: np.random.Generator, mats: _Materials, blocks_path: Callable[..., bool]) -> None:
    """Olive trees and cypresses scattered around the village, off the square and the flight corridor."""
    olive = tree_mesh("OliveTree", [mats.bark, mats.leaves[0]], 6.0, 3)
    cypress = tree_mesh("Cypress", [mats.bark, mats.leaves[1]], 9.0, 1)
    for i in range(150):
        r = float(rng.uniform(20.0, 140.0))
        a = float(rng.uniform(0, 2 * math.pi))
        x, y = r * math.cos(a), r * math.sin(a)
        if abs(x) < 16 and abs(y) < 16:
            continue
        mesh = cypress if rng.random() < 0.35 else olive
        s = float(rng.uniform(0.7, 1.3))
        if blocks_path(x, y, float(ground_height(x, y)) + 19.0, 6.0):
            continue
        c.add_object(f"Tree{i}", mesh, (x, y, float(ground_height(x, y)) - 0.2), (0, 0, float(a)),
                     (s, s, s * (1.6 if mesh is cypress else 1.0)))


def _church_and_fountain(mats: _Materials, sq_z: float) -> None:
    """A church with a bell tower on the square's north side, a turned stone fountain in its middle."""
    church = house_mesh("Church", 14, 24, 12, [mats.stone, mats.roof, mats.window, mats.wood])
    c.add_object("Church", church, (0.0, 30.0, sq_z - 0.2), (0, 0, math.pi / 2))
    c.box("BellTower", (5.0, 5.0, 26.0), (10.0, 24.0, sq_z + 12.8), mats.stone)
    basin = c.lathe("Basin", [(0.0, 0.0), (3.0, 0.0), (3.0, 0.8), (2.7, 0.8), (2.7, 0.25), (0.6, 0.25),
                              (0.5, 1.8), (1.0, 2.0), (1.0, 2.2), (0.0, 2.3)], mats.stone, steps=64)
    c.add_object("Fountain", basin, (0.0, 0.0, sq_z + 0.1))
    pool = c.lathe("Pool", [(0.0, 0.2), (2.68, 0.2), (2.68, 0.65), (0.0, 0.65)], mats.water, steps=64)
    c.add_object("Pool", pool, (0.0, 0.0, sq_z + 0.1))


def _street_lamps(mats: _Materials, sq_z: float) -> None:
    """Street lamps around the square (emissive globes; four also cast light)."""
    post_profile = [(0.0, 0.0), (0.15, 0.0), (0.08, 0.3), (0.06, 3.6), (0.0, 3.6)]
    post = c.lathe("LampPost", post_profile, mats.iron, steps=16)
    globe = c.uv_sphere_mesh("LampGlobe", segments=16, rings=8, radius=0.25, material=mats.lamp_glow)
    for i in range(12):
        a = 2 * math.pi * i / 12
        x, y = 13.5 * math.cos(a), 13.5 * math.sin(a)
        c.add_object(f"LampPost{i}", post, (x, y, sq_z + 0.1))
        c.add_object(f"LampGlobe{i}", globe, (x, y, sq_z + 3.85))
        if i % 3 == 0:
            c.point_light(f"Lamp{i}", (x, y, sq_z + 3.85), watts=120.0, color=(1.0, 0.8, 0.55), radius=0.25)
