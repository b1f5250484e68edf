"""Hall: a colonnaded interior lit mostly by the sun through an open door, the Stanford bunny as a
marble statue in the middle (seed: indoor scenes with hard light and dark corners)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import common as c

DURATION_S = 57.0
LENGTH, WIDTH, HEIGHT, THICK = 16.0, 8.0, 6.0, 0.3
DOOR_W, DOOR_H = 2.4, 3.6


def _column_profile() -> list[tuple[float, float]]:
    base = [(0.0, 0.0), (0.45, 0.0), (0.45, 0.25), (0.38, 0.3), (0.34, 0.4)]
    # Fluted look from a slight entasis (bulge) along the shaft.
    shaft = [(0.3 + 0.03 * math.sin(math.pi * s), 0.4 + s * (HEIGHT - 1.0)) for s in np.linspace(0, 1, 24)]
    capital = [(0.36, HEIGHT - 0.5), (0.48, HEIGHT - 0.3), (0.5, HEIGHT - 0.3), (0.5, HEIGHT), (0.0, HEIGHT)]
    return base + shaft + capital


def build(out_dir: Path) -> c.SceneSpec:
    c.reset()
    stone = c.principled("WallStone", (0.62, 0.58, 0.52), roughness=0.85)
    floor = c.principled("PolishedFloor", (0.35, 0.3, 0.28), roughness=0.18)
    ceiling = c.principled("Ceiling", (0.7, 0.68, 0.64), roughness=0.9)
    marble = c.principled("Marble", (0.92, 0.9, 0.86), roughness=0.3)
    ground = c.principled("Courtyard", (0.55, 0.5, 0.4), roughness=0.9)
    door = c.principled("DoorWood", (0.28, 0.14, 0.07), roughness=0.6)

    hx, hy = LENGTH / 2, WIDTH / 2
    c.box("Floor", (LENGTH, WIDTH, 0.2), (0.0, 0.0, -0.1), floor)
    c.box("Ceiling", (LENGTH, WIDTH, 0.2), (0.0, 0.0, HEIGHT + 0.1), ceiling)
    c.box("WallNorth", (LENGTH + 2 * THICK, THICK, HEIGHT), (0.0, hy + THICK / 2, HEIGHT / 2), stone)
    c.box("WallSouth", (LENGTH + 2 * THICK, THICK, HEIGHT), (0.0, -hy - THICK / 2, HEIGHT / 2), stone)
    c.box("WallWest", (THICK, WIDTH, HEIGHT), (-hx - THICK / 2, 0.0, HEIGHT / 2), stone)
    # East wall with the door: two side pieces and a lintel.
    side = (WIDTH - DOOR_W) / 2
    x = hx + THICK / 2
    c.box("WallEastL", (THICK, side, HEIGHT), (x, -hy + side / 2, HEIGHT / 2), stone)
    c.box("WallEastR", (THICK, side, HEIGHT), (x, hy - side / 2, HEIGHT / 2), stone)
    c.box("Lintel", (THICK, DOOR_W, HEIGHT - DOOR_H), (x, 0.0, (HEIGHT + DOOR_H) / 2), stone)
    leaf_at = (hx + THICK + DOOR_W / 4 + 0.05, -DOOR_W / 2 - 0.3, DOOR_H / 2)  # swung open outwards
    c.box("DoorLeaf", (DOOR_W / 2, 0.08, DOOR_H), leaf_at, door, rotation=(0.0, 0.0, math.radians(-35)))
    c.box("Courtyard", (30.0, 30.0, 0.2), (hx + 15.0, 0.0, -0.12), ground)

    column = c.lathe("Column", _column_profile(), stone, steps=48)
    for i in range(5):
        for j, y in enumerate((-2.6, 2.6)):
            c.add_object(f"Column{i}{j}", column, (-6.0 + i * 3.0, y, 0.0))

    bunny = c.import_obj(c.MODELS_DIR / "stanford-bunny.obj", "Bunny", marble)
    c.normalise(bunny, 1.4, (0.0, 0.0, 1.0))
    c.box("Pedestal", (1.4, 1.0, 1.0), (0.0, 0.0, 0.5), marble)

    # Late-afternoon sun low through the door, a dim lamp inside, a bright sky outside.
    c.sun_light("Sun", (-1.0, 0.15, -0.35), strength=6.0, color=(1.0, 0.9, 0.75), angle_deg=1.0)
    c.point_light("Lantern", (-6.5, 0.0, 4.5), watts=400.0, color=(1.0, 0.7, 0.4), radius=0.15)
    c.world_color((0.5, 0.62, 0.8))

    path_eye = c.smooth_path([(6.5, 1.5, 1.7), (3.5, -1.0, 1.6), (1.5, -1.4, 1.4), (-1.5, -1.3, 1.5),
                              (-2.5, 0.5, 1.9), (-1.0, 1.4, 1.6), (2.0, 1.3, 1.6), (5.0, -0.5, 1.8)],
                             DURATION_S)
    path_target = c.smooth_path([(0.0, 0.0, 1.7), (0.0, 0.0, 1.6), (0.0, 0.0, 1.6), (0.2, 0.0, 1.6),
                                 (0.0, 0.0, 1.7), (-6.0, 0.0, 2.5), (8.0, 0.0, 1.8), (0.0, 0.0, 1.8)],
                                DURATION_S)
    cam = c.animated_camera(path_eye, path_target, DURATION_S, lens_mm=24.0)
    return c.SceneSpec("hall", "Colonnaded hall lit by the sun through a door, Stanford bunny statue", cam,
                       DURATION_S)
