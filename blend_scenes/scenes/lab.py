"""Lab: glassware (beakers, Erlenmeyer and round flasks, test tubes) with coloured liquids on a bench,
several lights: refraction-heavy, a few hundred thousand triangles (seed: glass test scenes)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import common as c

DURATION_S = 58.0
STEPS = 72  # lathe segments around the axis


def _resample(points: list[tuple[float, float]], n: int) -> list[tuple[float, float]]:
    """n points evenly spaced by arc length along a (radius, height) polyline, ends kept."""
    p = np.asarray(points, dtype=np.float64)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    u = np.linspace(0.0, s[-1], n)
    return [(float(np.interp(x, s, p[:, 0])), float(np.interp(x, s, p[:, 1]))) for x in u]


def _solid(outer: list[tuple[float, float]], n: int) -> list[tuple[float, float]]:
    """Closed profile of a solid body: the outer surface from the axis up to the rim, then back to the axis.
    Glassware is modelled solid (two interfaces per object) so that a Whitted tracer with a depth of 2-4
    sees through it; a hollow thick-walled vessel needs six or more refraction bounces and renders black."""
    out = _resample(outer, n)
    return [*out, (0.0, out[-1][1])]


def _split(outer: list[tuple[float, float]], level: float, n: int, gap: float = 0.001
           ) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
    """Cut a body at `level`: the liquid below and the glass above as two closed solids, a hair apart
    (no coincident faces)."""
    out = np.asarray(_resample(outer, n))
    r_at = float(np.interp(level, out[:, 1], out[:, 0]))  # profiles rise monotonically until the rim
    below = [(float(r), float(z)) for r, z in out if z < level - gap / 2]
    above = [(float(r), float(z)) for r, z in out if z > level + gap / 2]
    lower = [*below, (r_at, level - gap / 2), (0.0, level - gap / 2)]
    upper = [(0.0, level + gap / 2), (r_at, level + gap / 2), *above, (0.0, out[-1, 1])]
    return lower, upper


def beaker(radius: float, height: float) -> list[tuple[float, float]]:
    return [(0.0, 0.0), (radius, 0.0), (radius, height), (radius * 1.06, height + 0.004)]


def erlenmeyer(radius: float, height: float) -> list[tuple[float, float]]:
    neck = radius * 0.3
    return [(0.0, 0.0), (radius, 0.0), (radius, 0.01), (neck, height * 0.7), (neck, height),
            (neck * 1.15, height + 0.004)]


def round_flask(radius: float, neck_len: float) -> list[tuple[float, float]]:
    neck = radius * 0.28
    top_angle = math.asin(neck / radius)
    angles = np.linspace(-math.pi / 2, math.pi / 2 - top_angle, 40)
    sphere = [(radius * math.cos(a), radius + radius * math.sin(a)) for a in angles]
    z0 = sphere[-1][1]
    return [*sphere, (neck, z0 + neck_len), (neck * 1.15, z0 + neck_len + 0.004)]


def tube(radius: float, height: float) -> list[tuple[float, float]]:
    angles = np.linspace(-math.pi / 2, 0.0, 10)
    return [*((radius * math.cos(a), radius + radius * math.sin(a)) for a in angles), (radius, height)]


def build(out_dir: Path) -> c.SceneSpec:
    c.reset()
    glass = c.principled("LabGlass", (0.97, 0.99, 1.0), roughness=0.01, transmission=1.0, ior=1.47)
    liquids = [
        c.principled("BlueLiquid", (0.25, 0.5, 0.95), roughness=0.02, transmission=1.0, ior=1.33),
        c.principled("GreenLiquid", (0.3, 0.9, 0.4), roughness=0.02, transmission=1.0, ior=1.34),
        c.principled("AmberLiquid", (0.95, 0.6, 0.15), roughness=0.02, transmission=1.0, ior=1.36),
    ]
    bench = c.principled("BenchTop", (0.08, 0.09, 0.1), roughness=0.3)
    steel = c.principled("Steel", (0.7, 0.7, 0.72), metallic=1.0, roughness=0.35)
    wall = c.principled("Wall", (0.75, 0.78, 0.8), roughness=0.8)
    floor = c.principled("Floor", (0.4, 0.42, 0.45), roughness=0.6)
    panel = c.principled("LightPanel", (1.0, 1.0, 1.0), emission=(1.0, 0.98, 0.92), emission_strength=2.0)

    # Room and furniture.
    c.box("Floor", (8.0, 6.0, 0.1), (0.0, 0.0, -0.05), floor)
    c.box("BackWall", (8.0, 0.1, 3.2), (0.0, 1.55, 1.6), wall)
    c.box("SideWall", (0.1, 6.0, 3.2), (-4.0, 0.0, 1.6), wall)
    c.box("Bench", (4.0, 1.0, 0.06), (0.0, 0.9, 0.92), bench)
    for i, x in enumerate((-1.9, 1.9)):
        c.box(f"BenchLeg{i}", (0.08, 0.9, 0.9), (x, 0.9, 0.45), steel)
    c.box("Shelf", (3.6, 0.3, 0.03), (0.0, 1.35, 1.6), steel)
    c.box("LightPanel", (1.2, 0.4, 0.02), (0.0, 0.8, 2.9), panel)
    c.box("Rack", (0.5, 0.08, 0.12), (1.2, 0.7, 1.01), steel)

    # Glassware: one mesh per (kind, liquid), shared by its instances (instancing).
    def filled(name: str, outer: list[tuple[float, float]], level: float, n: int, steps: int) -> list:
        lower, upper = _split(outer, level, n)
        glass_part = c.lathe(f"{name}Glass", upper, glass, steps)
        return [(glass_part, c.lathe(f"{name}Liquid{i}", lower, m, steps)) for i, m in enumerate(liquids)]

    beakers = filled("Beaker", beaker(0.045, 0.12), 0.07, 60, STEPS)
    erlenmeyers = filled("Erlenmeyer", erlenmeyer(0.06, 0.17), 0.06, 70, STEPS)
    tubes = filled("TestTube", tube(0.008, 0.15), 0.09, 40, 48)
    flask_mesh = c.lathe("RoundFlask", _solid(round_flask(0.06, 0.12), 80), glass, STEPS)
    top = 0.95
    rng = np.random.default_rng(7)

    def place(name: str, parts: tuple, location: tuple, rotation: tuple = (0.0, 0.0, 0.0)) -> None:
        for part, suffix in zip(parts, ("", "Liquid"), strict=True):
            c.add_object(f"{name}{suffix}", part, location, rotation)

    for i in range(8):
        place(f"Beaker{i}", beakers[i % 3], (-1.7 + i * 0.22, 0.75 + 0.12 * (i % 2), top))
    for i in range(7):
        place(f"Erlenmeyer{i}", erlenmeyers[(i + 1) % 3], (-0.05 + i * 0.2, 0.6 + 0.1 * (i % 2), top))
    for i in range(5):
        c.add_object(f"RoundFlask{i}", flask_mesh, (-1.6 + i * 0.36, 1.35, 1.615))
    for i in range(24):
        tilt = (float(rng.normal(0, 0.02)), 0.0, 0.0)
        at = (0.99 + (i % 12) * 0.038, 0.68 + 0.04 * (i // 12), top + 0.01)
        place(f"TestTube{i}", tubes[i % 3], at, tilt)

    c.point_light("CeilingA", (-1.5, 0.0, 2.8), watts=120.0, radius=0.2)
    c.point_light("CeilingB", (1.5, 0.0, 2.8), watts=120.0, radius=0.2)
    c.point_light("Fill", (0.0, -2.5, 1.8), watts=80.0, color=(0.85, 0.9, 1.0), radius=0.3)
    c.spot_light("DeskLamp", (0.9, 0.2, 1.7), (0.9, 0.8, 0.95), watts=40.0, angle_deg=40.0,
                 color=(1.0, 0.9, 0.75))
    c.world_color((0.02, 0.02, 0.025))

    path_eye = c.smooth_path([(-1.7, -0.1, 1.3), (-0.7, 0.05, 1.15), (0.4, -0.1, 1.2), (1.3, 0.1, 1.15),
                              (1.1, -0.6, 1.5), (-0.4, -0.8, 1.6)], DURATION_S)
    path_target = c.smooth_path([(-1.4, 0.8, 1.0), (-0.4, 0.7, 1.0), (0.5, 0.7, 1.05), (1.2, 0.7, 1.02),
                                 (0.6, 1.1, 1.3), (-0.8, 1.2, 1.4)], DURATION_S)
    cam = c.animated_camera(path_eye, path_target, DURATION_S, lens_mm=35.0)
    return c.SceneSpec("lab", "Lab bench: solid glassware and liquids (refraction), 4 lights, a light panel",
                       cam, DURATION_S)
