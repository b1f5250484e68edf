"""Valley: a river valley terrain (>= 300K triangles) under a low sun and a procedural sky saved as an
equirectangular EXR; water and polished boulders make glossy environment reflections matter (seed:
outdoor terrain scenes, glossy environment filtering)."""

from __future__ import annotations

import math
from pathlib import Path

import bpy
import numpy as np
from sim_core.image import write_exr

from .. import common as c

DURATION_S = 55.0
SIZE = 400.0  # metres
GRID = 400  # vertices per side: 2 * 399^2 = 318,402 triangles
WATER_LEVEL = 1.5
SUN_DIRECTION = np.array([-0.55, 0.6, -0.35])  # the way sunlight travels
ENV_SIZE = (512, 1024)  # (H, W)

_RNG = np.random.default_rng(2024)
_N_WAVES = 48
_FREQ = 2 * math.pi / SIZE * np.exp(_RNG.uniform(math.log(1.5), math.log(60.0), _N_WAVES))
_ANGLE = _RNG.uniform(0, 2 * math.pi, _N_WAVES)
_PHASE = _RNG.uniform(0, 2 * math.pi, _N_WAVES)
_AMP = 9.0 * (_FREQ / _FREQ.min()) ** -1.1


def height(x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
    """Terrain height (m): a meandering valley along X between ridges, plus spectral noise. Closed form,
    so the camera path can stay above the ground."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    centre = 25.0 * np.sin(x / 60.0)  # the river meanders
    d = (y - centre) / 90.0
    valley = 55.0 * d * d / (1.0 + 0.6 * np.abs(d))
    noise = np.zeros(np.broadcast(x, y).shape)
    for f, a, p, amp in zip(_FREQ, _ANGLE, _PHASE, _AMP, strict=True):
        noise += amp * np.sin(f * (x * math.cos(a) + y * math.sin(a)) + p)
    ridge_weight = np.clip(np.abs(d) * 1.5, 0.15, 1.0)
    return valley + noise * ridge_weight


def sky(height_px: int, width_px: int) -> np.ndarray:
    """Equirectangular sky (Blender's convention: row 0 is the zenith, u = 0.5 - atan2(y, x) / 2 pi):
    a zenith-to-horizon gradient, a darker ground, a bright sun disc with a glow."""
    v = 1.0 - (np.arange(height_px) + 0.5) / height_px
    u = (np.arange(width_px) + 0.5) / width_px
    elev = (v - 0.5) * math.pi
    azim = -(u - 0.5) * 2 * math.pi
    el, az = np.meshgrid(elev, azim, indexing="ij")
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
    up = np.clip(np.sin(el), 0.0, 1.0)[..., None]
    zenith, horizon = np.array([0.12, 0.28, 0.7]), np.array([0.75, 0.82, 0.9])
    img = horizon + (zenith - horizon) * np.sqrt(up)
    ground = np.array([0.18, 0.16, 0.13])
    below = np.clip(-np.sin(el) * 8.0, 0.0, 1.0)[..., None]
    img = img * (1 - below) + ground * below
    to_sun = -SUN_DIRECTION / np.linalg.norm(SUN_DIRECTION)
    cos_a = np.clip(d @ to_sun, -1.0, 1.0)
    ang = np.arccos(cos_a)
    img += np.array([1.0, 0.9, 0.7]) * (0.6 * np.exp(-ang / 0.15))[..., None]  # glow
    img += np.array([1.0, 0.95, 0.85]) * (200.0 * (ang < math.radians(1.0)))[..., None]  # disc
    return img.astype(np.float32)


def build(out_dir: Path) -> c.SceneSpec:
    c.reset()
    grass = c.principled("Grass", (0.22, 0.35, 0.12), roughness=0.9)
    rock = c.principled("Rock", (0.4, 0.38, 0.35), roughness=0.7)
    snow = c.principled("Snow", (0.9, 0.92, 0.95), roughness=0.45)
    water = c.principled("Water", (0.05, 0.12, 0.15), roughness=0.08)
    granite = c.principled("PolishedGranite", (0.3, 0.3, 0.32), metallic=0.6, roughness=0.35)

    xs = np.linspace(-SIZE / 2, SIZE / 2, GRID)
    gx, gy = np.meshgrid(xs, xs)
    h = height(gx, gy)
    terrain = c.grid_mesh("Terrain", h, SIZE, SIZE, None)
    # Material per face from height and slope: grass low and flat, rock steep, snow high.
    hc = (h[:-1, :-1] + h[1:, 1:]) / 2
    cell = SIZE / (GRID - 1)
    slope = np.hypot(h[1:, :-1] - h[:-1, :-1], h[:-1, 1:] - h[:-1, :-1]) / cell
    mat = np.where(hc > 45.0, 2, np.where(slope > 0.8, 1, 0)).reshape(-1)
    for m in (grass, rock, snow):
        terrain.materials.append(m)
    terrain.polygons.foreach_set("material_index", mat.astype(np.int32))
    c.add_object("Terrain", terrain)
    c.box("Water", (SIZE, SIZE, 0.2), (0.0, 0.0, WATER_LEVEL - 0.1), water)

    rng = np.random.default_rng(11)
    # bmesh-free icosphere through the primitive operator, then shared by all boulders
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.0)
    ico = bpy.context.active_object
    boulder = ico.data
    boulder.name = "Boulder"
    boulder.materials.append(granite)
    for poly in boulder.polygons:
        poly.use_smooth = True
    bpy.data.objects.remove(ico)
    for i in range(40):
        x = float(rng.uniform(-180, 180))
        y = float(25.0 * math.sin(x / 60.0) + rng.choice([-1, 1]) * rng.uniform(12, 40))
        s = float(rng.uniform(1.0, 3.5))
        c.add_object(f"Boulder{i}", boulder, (x, y, float(height(x, y)) + 0.3 * s),
                     (float(rng.uniform(0, 3)), float(rng.uniform(0, 3)), 0.0), (s, s * 0.8, s * 0.6))

    c.sun_light("Sun", tuple(SUN_DIRECTION), strength=3.0, angle_deg=1.0)
    env_path = out_dir / "environment.exr"
    write_exr(env_path, sky(*ENV_SIZE))
    c.world_exr(env_path)

    def eye(t: float) -> np.ndarray:  # fly down the valley, following the river, 20-35 m above it
        s = t / DURATION_S
        x = -170.0 + 320.0 * s
        y = 25.0 * math.sin(x / 60.0) - 30.0 * math.sin(2 * math.pi * s)
        ground = max(float(height(x, y)), WATER_LEVEL)
        return np.array([x, y, ground + 22.0 + 12.0 * math.sin(math.pi * s)])

    def target(t: float) -> np.ndarray:
        x = -170.0 + 320.0 * (t / DURATION_S) + 60.0
        y = 25.0 * math.sin(x / 60.0) + 20.0 * math.sin(2 * math.pi * t / DURATION_S)
        return np.array([x, y, max(float(height(x, y)), WATER_LEVEL) + 5.0])

    cam = c.animated_camera(eye, target, DURATION_S, lens_mm=24.0)
    return c.SceneSpec("valley", "River valley terrain, sun, procedural sky EXR, water, glossy boulders", cam,
                       DURATION_S, extra_files=[env_path])
