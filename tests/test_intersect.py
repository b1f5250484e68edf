"""Native closest-hit queries: watertightness, API contract, thread independence."""

from __future__ import annotations

import numpy as np
import pytest

import sim_core


def icosphere(subdivisions: int = 3, radius: float = 1.0, center=(0.0, 0.0, 0.0)):
    """Closed triangle mesh of a sphere (every edge shared by exactly two triangles)."""
    t = (1 + 5**0.5) / 2
    verts = [
        (-1, t, 0),
        (1, t, 0),
        (-1, -t, 0),
        (1, -t, 0),
        (0, -1, t),
        (0, 1, t),
        (0, -1, -t),
        (0, 1, -t),
        (t, 0, -1),
        (t, 0, 1),
        (-t, 0, -1),
        (-t, 0, 1),
    ]
    faces = [
        (0, 11, 5),
        (0, 5, 1),
        (0, 1, 7),
        (0, 7, 10),
        (0, 10, 11),
        (1, 5, 9),
        (5, 11, 4),
        (11, 10, 2),
        (10, 7, 6),
        (7, 1, 8),
        (3, 9, 4),
        (3, 4, 2),
        (3, 2, 6),
        (3, 6, 8),
        (3, 8, 9),
        (4, 9, 5),
        (2, 4, 11),
        (6, 2, 10),
        (8, 6, 7),
        (9, 8, 1),
    ]
    v = [np.asarray(p, float) / np.linalg.norm(p) for p in verts]
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = v[a] + v[b]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    pos = np.asarray(v) * radius + np.asarray(center)
    return pos.astype(np.float32), np.asarray(faces, np.int64)


def _edges(tri: np.ndarray) -> np.ndarray:
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


@pytest.mark.parametrize("center", [(0.0, 0.0, 0.0), (1e3, -2e3, 5e2)])
def test_rays_at_shared_edges_and_vertices_never_leak(center):
    pos, tri = icosphere(3, radius=1.0, center=center)
    scene = sim_core.Scene.from_arrays(pos, tri)
    rng = np.random.default_rng(3)
    edges = _edges(tri)
    p64 = pos.astype(np.float64)
    # Targets exactly at vertices and at points along shared edges (computed in float32 like any caller).
    ts = rng.random((len(edges), 1))
    edge_pts = p64[edges[:, 0]] * (1 - ts) + p64[edges[:, 1]] * ts
    targets = np.concatenate([p64, edge_pts, p64[edges[:, 0]] * 0.5 + p64[edges[:, 1]] * 0.5])
    c = np.asarray(center)
    # From outside: eye points in a cone around the outward normal at the target (so the ray meets the
    # surface there, not at a silhouette it might legitimately graze); from inside: jittered centre points.
    normal = _unit(targets - c)
    outside = targets + _unit(normal + 0.6 * rng.normal(size=targets.shape)) * 3.0
    facing = np.sum((outside - targets) * normal, axis=1) > 0.5
    outside = np.where(facing[:, None], outside, targets + normal * 3)
    inside = c + rng.normal(size=targets.shape) * 0.2
    for origins in (outside, inside):
        o = origins.astype(np.float32)
        d = (targets - origins).astype(np.float32)
        t, prim = scene.intersect(o, d)
        assert np.all(prim >= 0), f"{np.sum(prim < 0)} of {len(prim)} rays leaked through edges/vertices"
        assert np.all(np.isfinite(t))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_axis_aligned_rays_and_grazing_origins():
    # A unit cube (closed): axis-aligned rays through faces, edges and corners from outside must hit.
    pos = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tri = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], np.int64)
    scene = sim_core.Scene.from_arrays(pos, tri)
    grid = np.linspace(0.0, 1.0, 9, dtype=np.float32)
    gy, gz = np.meshgrid(grid, grid)
    o = np.stack([np.full(gy.size, -1.0, np.float32), gy.ravel(), gz.ravel()], axis=1)
    d = np.tile(np.array([[1.0, 0.0, 0.0]], np.float32), (len(o), 1))
    t, prim = scene.intersect(o, d)
    assert np.all(prim >= 0)
    np.testing.assert_allclose(t, 1.0, rtol=0, atol=1e-6)
    # Parallel to a face, outside the cube: miss.
    t, prim = scene.intersect(np.array([[-1, 0.5, 1.5]], np.float32), np.array([[1, 0, 0]], np.float32))
    assert prim[0] == -1 and np.isinf(t[0])


def test_prim_ids_refer_to_original_triangles_after_dropping_degenerates():
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [0, 0, 1], [0, 1, 1], [1, 0, 1]], np.float32)
    tri = np.array([[0, 1, 3], [0, 0, 1], [4, 6, 5], [0, 1, 2]], np.int64)  # 0 collinear, 1 repeated index
    scene = sim_core.Scene.from_arrays(pos, tri)
    assert scene.stats["triangles"] == 2 and scene.stats["degenerate_dropped"] == 2
    o = np.array([[0.2, 0.2, 2.0], [0.2, 0.2, 0.5]], np.float32)
    d = np.array([[0, 0, -1], [0, 0, -1]], np.float32)
    t, prim = scene.intersect(o, d)
    assert prim.tolist() == [2, 3]
    np.testing.assert_allclose(t, [1.0, 0.5], rtol=1e-6)


def test_distance_is_in_units_of_direction_length():
    pos, tri = icosphere(2)
    scene = sim_core.Scene.from_arrays(pos, tri)
    o = np.array([[0, 0, 5.0]], np.float32)
    t1, _ = scene.intersect(o, np.array([[0, 0, -1.0]], np.float32))
    t2, _ = scene.intersect(o, np.array([[0, 0, -2.0]], np.float32))
    assert t1[0] == pytest.approx(4.0, rel=1e-2) and t2[0] == pytest.approx(t1[0] / 2, rel=1e-6)


def test_thread_count_does_not_change_results():
    pos, tri = icosphere(4)
    scene = sim_core.Scene.from_arrays(pos, tri)
    rng = np.random.default_rng(0)
    o = (rng.normal(size=(20_000, 3)) * 2).astype(np.float32)
    d = rng.normal(size=(20_000, 3)).astype(np.float32)
    a = scene.intersect(o, d, threads=1)
    b = scene.intersect(o, d, threads=2)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


@pytest.mark.parametrize(
    ("origins", "dirs", "match"),
    [
        (np.zeros((2, 3)), np.ones((3, 3)), "same shape"),
        (np.zeros((2, 2)), np.ones((2, 2)), r"shape \(N, 3\)"),
        (np.array([[np.nan, 0, 0]]), np.ones((1, 3)), "finite"),
        (np.zeros((1, 3)), np.array([[np.inf, 0, 0]]), "finite"),
        (np.zeros((1, 3)), np.zeros((1, 3)), "non-zero"),
    ],
)
def test_intersect_rejects_bad_rays(origins, dirs, match):
    pos, tri = icosphere(1)
    scene = sim_core.Scene.from_arrays(pos, tri)
    with pytest.raises(ValueError, match=match):
        scene.intersect(origins, dirs)


def test_empty_ray_batch():
    pos, tri = icosphere(1)
    scene = sim_core.Scene.from_arrays(pos, tri)
    t, prim = scene.intersect(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32))
    assert t.shape == (0,) and prim.shape == (0,)
