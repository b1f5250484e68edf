"""The Utah teapot on a polished floor under one light: the low-frequency scene (seed: teapot on a plane)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import common as c

DURATION_S = 55.0


def build(out_dir: Path) -> c.SceneSpec:
    c.reset()
    glaze = c.principled("TeapotGlaze", (0.72, 0.16, 0.10), roughness=0.35)
    floor = c.principled("PolishedFloor", (0.55, 0.55, 0.58), metallic=0.8, roughness=0.12)
    teapot = c.import_obj(c.MODELS_DIR / "teapot.obj", "Teapot", glaze)
    c.normalise(teapot, 2.0)  # about 2 m wide, standing on z = 0
    c.add_object("Floor", c.box_mesh("Floor", (24.0, 24.0, 0.1), floor), (0.0, 0.0, -0.05))
    c.point_light("KeyLight", (3.0, -2.5, 5.0), watts=1000.0, radius=0.15)
    c.world_color((0.05, 0.06, 0.08))

    def eye(t: float) -> np.ndarray:  # slow orbit with a gentle dolly and rise
        a = 2 * math.pi * t / DURATION_S - math.pi / 2
        r = 4.2 + 0.8 * math.sin(2 * math.pi * t / DURATION_S * 2)
        z = 1.6 + 0.8 * math.sin(2 * math.pi * t / DURATION_S)
        return np.array([r * math.cos(a), r * math.sin(a), z])

    cam = c.animated_camera(eye, lambda t: (0.0, 0.0, 0.55), DURATION_S, lens_mm=35.0)
    return c.SceneSpec("teapot", "Utah teapot on a polished floor, one point light", cam, DURATION_S)
