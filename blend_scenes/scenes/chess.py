"""Chess: a board with turned (lathe) pieces, the white set in glass and the black set as mirrors
(seed: reflection and refraction test scenes)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .. import common as c

DURATION_S = 56.0
SQUARE = 0.3  # metres per board square

# (radius, height) profiles, bottom to top, in units of one square; spun around Z by the Screw modifier.
_BASE = [(0.0, 0.0), (0.38, 0.0), (0.38, 0.06), (0.33, 0.09), (0.34, 0.12), (0.26, 0.16)]
PROFILES: dict[str, list[tuple[float, float]]] = {
    "pawn": [*_BASE, (0.17, 0.22), (0.12, 0.42), (0.2, 0.46), (0.12, 0.5), (0.17, 0.56), (0.19, 0.62),
             (0.17, 0.68), (0.1, 0.73), (0.0, 0.75)],
    "rook": [*_BASE, (0.24, 0.3), (0.2, 0.6), (0.27, 0.66), (0.27, 0.82), (0.2, 0.82), (0.2, 0.76),
             (0.0, 0.76)],
    "knight": [*_BASE, (0.2, 0.3), (0.16, 0.5), (0.24, 0.62), (0.22, 0.78), (0.14, 0.9), (0.06, 0.94),
               (0.0, 0.95)],
    "bishop": [*_BASE, (0.19, 0.28), (0.12, 0.6), (0.22, 0.64), (0.13, 0.68), (0.19, 0.8), (0.16, 0.9),
               (0.07, 0.98), (0.09, 1.02), (0.0, 1.05)],
    "queen": [*_BASE, (0.22, 0.3), (0.13, 0.75), (0.25, 0.8), (0.15, 0.85), (0.24, 1.02), (0.2, 1.06),
              (0.1, 1.08), (0.08, 1.13), (0.0, 1.15)],
    "king": [*_BASE, (0.22, 0.3), (0.14, 0.8), (0.26, 0.85), (0.15, 0.9), (0.23, 1.06), (0.12, 1.12),
             (0.05, 1.14), (0.05, 1.26), (0.0, 1.28)],
}
BACK_RANK = ["rook", "knight", "bishop", "queen", "king", "bishop", "knight", "rook"]


def _square_center(file: int, rank: int) -> tuple[float, float]:
    return ((file - 3.5) * SQUARE, (rank - 3.5) * SQUARE)


def build(out_dir: Path) -> c.SceneSpec:
    c.reset()
    light_sq = c.principled("LightSquare", (0.85, 0.8, 0.7), roughness=0.25)
    dark_sq = c.principled("DarkSquare", (0.12, 0.08, 0.06), roughness=0.25)
    frame_mat = c.principled("Walnut", (0.3, 0.16, 0.08), roughness=0.5)
    table = c.principled("Table", (0.35, 0.35, 0.38), roughness=0.7)
    glass = c.principled("Glass", (0.95, 0.97, 1.0), roughness=0.02, transmission=1.0, ior=1.5)
    mirror = c.principled("Mirror", (0.9, 0.9, 0.92), metallic=1.0, roughness=0.03)

    # Board: 64 squares as one mesh with two materials, a frame around it, a table below.
    verts, faces, mat_idx = [], [], []
    for rank in range(8):
        for file in range(8):
            x, y = _square_center(file, rank)
            h = SQUARE / 2
            base = len(verts)
            verts += [(x - h, y - h, 0.0), (x + h, y - h, 0.0), (x + h, y + h, 0.0), (x - h, y + h, 0.0)]
            faces.append((base, base + 1, base + 2, base + 3))
            mat_idx.append((file + rank) % 2)
    board = c.mesh_from_arrays("Board", np.array(verts), faces, [dark_sq, light_sq],
                               material_indices=np.array(mat_idx))
    c.add_object("Board", board)
    edge = 8 * SQUARE
    off = (edge + 0.15) / 2
    long_side, short_side = edge + 0.3, 0.15
    rails = [(long_side, short_side, 0, off), (long_side, short_side, 0, -off),
             (short_side, edge, off, 0), (short_side, edge, -off, 0)]
    for i, (sx, sy, x, y) in enumerate(rails):
        c.box(f"Frame{i}", (sx, sy, 0.08), (x, y, -0.03), frame_mat)
    c.box("Table", (6.0, 4.0, 0.1), (0.0, 0.0, -0.12), table)

    # Turned pieces: one lathe mesh per (type, colour), shared by every instance of it.
    meshes: dict[tuple[str, str], object] = {}
    for kind, profile in PROFILES.items():
        scaled = [(r * SQUARE, z * SQUARE) for r, z in profile]
        meshes[(kind, "white")] = c.lathe(f"{kind}_glass", scaled, glass, steps=40)
        meshes[(kind, "black")] = c.lathe(f"{kind}_mirror", scaled, mirror, steps=40)
    count = 0
    for colour, back, front in (("white", 0, 1), ("black", 7, 6)):
        for file in range(8):
            for rank, kind in ((back, BACK_RANK[file]), (front, "pawn")):
                x, y = _square_center(file, rank)
                # A few pieces moved, as in a game in progress.
                if kind == "pawn" and file in (3, 4):
                    y += (2 if colour == "white" else -2) * SQUARE * (1 if file == 4 else 0.5)
                turn = math.pi if colour == "black" else 0.0
                c.add_object(f"{colour}_{kind}_{count}", meshes[(kind, colour)], (x, y, 0.0), (0, 0, turn))
                count += 1

    c.point_light("Lamp", (1.2, -1.5, 2.4), watts=900.0, color=(1.0, 0.95, 0.85), radius=0.12)
    c.spot_light("Spot", (-2.0, 1.8, 2.6), (0.0, 0.0, 0.0), watts=1500.0, angle_deg=50.0, radius=0.05)
    c.world_color((0.04, 0.045, 0.06))

    def eye(t: float) -> np.ndarray:  # circle the board, swooping low over it once
        a = 2 * math.pi * t / DURATION_S + 0.4
        r = 2.6 - 0.7 * math.sin(math.pi * t / DURATION_S) ** 2
        z = 1.5 - 0.6 * math.sin(math.pi * t / DURATION_S) ** 2
        return np.array([r * math.cos(a), r * math.sin(a), z])

    def target(t: float) -> np.ndarray:
        a = 2 * math.pi * t / DURATION_S
        return np.array([0.25 * math.cos(3 * a), 0.25 * math.sin(2 * a), 0.12])

    cam = c.animated_camera(eye, target, DURATION_S, lens_mm=32.0)
    return c.SceneSpec("chess", "Chess board, 32 turned pieces: glass (white) and mirror (black), 2 lights",
                       cam, DURATION_S)
