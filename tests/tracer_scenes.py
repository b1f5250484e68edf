"""Small scenes built from the bundled models, shared by the tracer tests and benchmarks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sim_core.loaders import load_obj

import sim_core
from sim_core import Camera, Light, Material, Scene

MODELS = Path(__file__).resolve().parent.parent / "assets" / "models"


def with_ground(pos: np.ndarray, tri: np.ndarray, size: float = 10.0, subdiv: int = 4):
    """Appends a square ground plane (subdiv x subdiv quads) under the mesh; returns arrays + plane mask."""
    lo = pos.min(axis=0)
    z = lo[2]
    g = np.linspace(-size, size, subdiv + 1)
    gx, gy = np.meshgrid(g, g)
    gp = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], axis=1)
    quads = []
    for j in range(subdiv):
        for i in range(subdiv):
            a = j * (subdiv + 1) + i
            quads += [(a, a + 1, a + subdiv + 2), (a, a + subdiv + 2, a + subdiv + 1)]
    n0 = len(pos)
    p = np.vstack([pos, gp]).astype(np.float32)
    t = np.vstack([tri, np.asarray(quads) + n0]).astype(np.int64)
    ground = np.r_[np.zeros(len(tri), bool), np.ones(len(quads), bool)]
    return p, t, ground


def teapot_on_plane(metallic: float = 0.0, roughness: float = 0.4, environment=(0.3, 0.35, 0.4)) -> Scene:
    d = load_obj(MODELS / "teapot.obj")
    p, t, ground = with_ground(d.positions, d.triangles)
    n = sim_core.smooth_normals(p, t)
    mats = [
        Material(base_color=(0.8, 0.3, 0.2), metallic=metallic, roughness=roughness),
        Material(base_color=(0.7, 0.7, 0.7), roughness=0.9),
    ]
    ids = ground.astype(np.int64)
    light = Light(kind="point", position=(4.0, -4.0, 8.0), intensity=300.0, radius=0.5)
    return Scene.from_arrays(
        p,
        t,
        normals=n,
        material_ids=ids,
        object_ids=ids,
        materials=mats,
        lights=[light],
        environment=environment,
    )


def teapot_camera(width: int = 160, height: int = 120) -> Camera:
    return Camera.look_at((0.0, -9.0, 5.0), (0.0, 0.0, 1.0), (0.0, 0.0, 1.0), 0.7, width, height)


def effects_scene(environment=None) -> Scene:
    """Bunny (glass), spot (mirror metal), cow (glossy metal) on a diffuse plane: every secondary effect."""
    parts, tris, mids = [], [], []
    offset = 0
    placements = [
        ("stanford-bunny.obj", (-2.2, 0.0), 2),
        ("spot.obj", (0.0, 0.5), 3),
        ("cow.obj", (2.2, 0.0), 4),
    ]
    for i, (name, (x, y), mid) in enumerate(placements):
        d = load_obj(MODELS / name)
        p = d.positions.astype(np.float64)
        lo, hi = p.min(axis=0), p.max(axis=0)
        s = 1.8 / float(np.max(hi - lo))
        p = (p - (lo + hi) / 2) * s
        p[:, 2] -= p[:, 2].min()
        p[:, 0] += x
        p[:, 1] += y
        parts.append(p)
        tris.append(d.triangles.astype(np.int64) + offset)
        mids.append(np.full(len(d.triangles), mid + 0 * i))
        offset += len(p)
    pos = np.vstack(parts)
    tri = np.vstack(tris)
    p, t, ground = with_ground(pos, tri, size=8.0)
    mid = np.r_[np.concatenate(mids), np.zeros(ground.sum(), np.int64)]
    mats = [
        Material(base_color=(0.6, 0.6, 0.6), roughness=0.8),
        Material(base_color=(0.9, 0.9, 0.9)),
        Material(base_color=(0.95, 0.95, 1.0), roughness=0.0, transmission=1.0, ior=1.5),
        Material(base_color=(0.9, 0.8, 0.6), metallic=1.0, roughness=0.0),
        Material(base_color=(0.8, 0.8, 0.85), metallic=1.0, roughness=0.35),
    ]
    lights = [
        Light(kind="point", position=(3.0, -4.0, 6.0), intensity=250.0, radius=0.3),
        Light(kind="sun", direction=(0.3, 0.5, -1.0), intensity=1.5, radius=0.02),
    ]
    n = sim_core.smooth_normals(p, t)
    return Scene.from_arrays(
        p,
        t,
        normals=n,
        material_ids=mid,
        object_ids=mid,
        materials=mats,
        lights=lights,
        environment=environment if environment is not None else (0.4, 0.45, 0.5),
    )


def effects_camera(width: int = 160, height: int = 90) -> Camera:
    return Camera.look_at((0.0, -7.0, 3.0), (0.0, 0.0, 0.8), (0.0, 0.0, 1.0), 0.6, width, height)


def sky_map(height: int = 32, width: int = 64) -> np.ndarray:
    """A small equirectangular sky: blue gradient with a bright sun patch (row 0 = zenith)."""
    v = (np.arange(height) + 0.5) / height
    sky = np.zeros((height, width, 3), np.float32)
    sky[..., 0] = 0.3 + 0.5 * v[:, None]
    sky[..., 1] = 0.4 + 0.4 * v[:, None]
    sky[..., 2] = 0.9 - 0.3 * v[:, None]
    sky[height // 4 : height // 4 + 3, width // 3 : width // 3 + 4] = 20.0
    return sky


def teapot_scene() -> sim_core.Scene:
    """The bundled teapot, mirror-like, on a diffuse ground under a soft point light (module level, so
    worker processes can rebuild it)."""
    d = load_obj(MODELS / "teapot.obj")
    pos = np.asarray(d.positions, dtype=np.float64)
    tri = np.asarray(d.triangles, dtype=np.int64)
    z = float(pos[:, 2].min())
    g = np.array([[-8, -8, z], [8, -8, z], [8, 8, z], [-8, 8, z]], dtype=np.float64)
    p = np.vstack([pos, g]).astype(np.float32)
    n0 = len(pos)
    t = np.vstack([tri, [[n0, n0 + 1, n0 + 2], [n0, n0 + 2, n0 + 3]]])
    ids = np.r_[np.zeros(len(tri), np.int64), np.ones(2, np.int64)]
    mats = [sim_core.Material(base_color=(0.8, 0.3, 0.2), metallic=1.0, roughness=0.2),
            sim_core.Material(base_color=(0.7, 0.7, 0.7), roughness=0.9)]
    light = sim_core.Light(kind="point", position=(4.0, -4.0, 8.0), intensity=300.0, radius=0.5)
    return sim_core.Scene.from_arrays(p, t, normals=sim_core.smooth_normals(p, t), material_ids=ids,
                                      object_ids=ids, materials=mats, lights=[light],
                                      environment=(0.3, 0.35, 0.4))
