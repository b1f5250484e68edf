"""Closest-hit queries against Embree (embreex) on the bundled teapot and bunny.

Same rays to both tracers: camera rays from several views, rays between random points around the mesh,
and rays leaving points on the surface (offset by 1e-5 of the scene size along the normal, so neither
tracer sees its own starting triangle). Hit/miss must agree on >= 99.99 % of rays and hit distances must
agree to 1e-4 relative. Embree (non-robust mode) and the watertight test may only disagree on rays that
graze an edge or vertex; the agreement threshold leaves room for those and nothing else.
"""

from __future__ import annotations

import numpy as np
import pytest
from sim_core.loaders import load_obj

import sim_core

embreex = pytest.importorskip("embreex")
from embreex import rtcore_scene  # noqa: E402
from embreex.mesh_construction import TriangleMesh  # noqa: E402


def _camera_rays(center: np.ndarray, radius: float, views: int, res: int, rng: np.random.Generator):
    origins, dirs = [], []
    for _ in range(views):
        v = rng.normal(size=3)
        eye = center + v / np.linalg.norm(v) * radius * rng.uniform(1.5, 3.0)
        fwd = (center - eye) / np.linalg.norm(center - eye)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        ys, xs = np.mgrid[0:res, 0:res]
        u = (xs + 0.5) / res * 2 - 1
        w = 1 - (ys + 0.5) / res * 2
        t = np.tan(0.45)
        d = fwd + u[..., None] * t * right + w[..., None] * t * up
        d = d.reshape(-1, 3)
        dirs.append(d / np.linalg.norm(d, axis=1, keepdims=True))
        origins.append(np.broadcast_to(eye, d.shape))
    return np.concatenate(origins), np.concatenate(dirs)


def _ray_set(positions: np.ndarray, triangles: np.ndarray, seed: int = 0):
    rng = np.random.default_rng(seed)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    center = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2
    o1, d1 = _camera_rays(center, radius, views=4, res=128, rng=rng)  # 65,536 camera rays
    n2 = 30_000  # random rays between points in and around the bounding sphere
    o2 = center + rng.normal(size=(n2, 3)) * radius
    t2 = center + rng.normal(size=(n2, 3)) * radius * 0.3
    d2 = t2 - o2
    d2 /= np.linalg.norm(d2, axis=1, keepdims=True)
    n3 = 20_000  # rays leaving the surface into the hemisphere of the geometric normal
    tri = rng.integers(0, len(triangles), n3)
    a, b, c = (positions[triangles[tri, k]].astype(np.float64) for k in range(3))
    r1, r2 = rng.random(n3), rng.random(n3)
    s = np.sqrt(r1)
    p = (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c
    nrm = np.cross(b - a, c - a)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    d3 = rng.normal(size=(n3, 3))
    d3 /= np.linalg.norm(d3, axis=1, keepdims=True)
    d3 = np.where((np.sum(d3 * nrm, axis=1) < 0)[:, None], -d3, d3)
    o3 = p + nrm * 1e-5 * radius * 2
    origins = np.concatenate([o1, o2, o3]).astype(np.float32)
    dirs = np.concatenate([d1, d2, d3]).astype(np.float32)
    return origins, dirs


@pytest.mark.parametrize("model", ["teapot.obj", "stanford-bunny.obj"])
def test_matches_embree(models_dir, model):
    data = load_obj(models_dir / model)
    pos = data.positions.astype(np.float32)
    tri = data.triangles.astype(np.int64)
    scene = sim_core.Scene.from_arrays(pos, tri)
    origins, dirs = _ray_set(pos, tri)
    assert len(origins) >= 100_000

    t, prim = scene.intersect(origins, dirs, threads=2)
    es = rtcore_scene.EmbreeScene()
    TriangleMesh(es, pos, tri.astype(np.int32))
    ref = es.run(origins, dirs, output=1)
    ref_hit = ref["primID"] >= 0
    hit = prim >= 0

    assert t.dtype == np.float32 and prim.dtype == np.int64
    assert np.all(np.isinf(t[~hit])) and np.all(prim[~hit] == -1)
    agree = np.mean(hit == ref_hit)
    assert agree >= 0.9999, f"hit/miss agree on only {agree:.6%} of {len(t)} rays"
    both = hit & ref_hit
    assert both.sum() > 0.2 * len(t)  # the ray set really exercises hits
    rel = np.abs(t[both] - ref["tfar"][both]) / ref["tfar"][both]
    assert float(rel.max()) <= 1e-4, f"max relative distance error {rel.max():.3g}"
    # Same triangle for almost all hits (ties at shared edges may pick either neighbour).
    assert np.mean(prim[both] == ref["primID"][both]) >= 0.999


@pytest.mark.parametrize("model", ["teapot.obj", "stanford-bunny.obj"])
def test_occlusion_matches_embree(models_dir, model):
    """Any-hit queries (shadow and AO rays) on bounded segments: occluded exactly when Embree's rtcOccluded
    says so, and exactly when the closest hit lies inside the segment."""
    data = load_obj(models_dir / model)
    pos = data.positions.astype(np.float32)
    tri = data.triangles.astype(np.int64)
    scene = sim_core.Scene.from_arrays(pos, tri)
    origins, dirs = _ray_set(pos, tri, seed=1)
    rng = np.random.default_rng(2)
    diag = float(np.linalg.norm(pos.max(axis=0) - pos.min(axis=0)))
    tmax = (rng.random(len(origins)) * diag).astype(np.float32)
    tmax[::7] = np.inf
    occluded = scene.occluded(origins, dirs, tmax, threads=2)
    t, _ = scene.intersect(origins, dirs, threads=2)
    np.testing.assert_array_equal(occluded, t < tmax)
    t_bounded, _ = scene.intersect(origins, dirs, threads=2, tmax=tmax)
    np.testing.assert_array_equal(occluded, np.isfinite(t_bounded))
    es = rtcore_scene.EmbreeScene()
    TriangleMesh(es, pos, tri.astype(np.int32))
    ref = es.run(origins, dirs, dists=np.where(np.isinf(tmax), np.float32(1e37), tmax), query="OCCLUDED") >= 0
    assert 0.05 < occluded.mean() < 0.95
    agree = np.mean(occluded == ref)
    assert agree >= 0.9999, f"occlusion agrees with Embree on only {agree:.6%} of {len(t)} rays"
