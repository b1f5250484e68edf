"""Streaming traversal (thesis ch. 3): same closest hits as per-ray traversal, far fewer scene fetches."""

from __future__ import annotations

import numpy as np
import pytest
from sim_core.scene import Scene
from sim_core.streaming import compare_traversal, pinhole_rays, reflection_rays, traverse

from sim_core import _core


@pytest.fixture(scope="module")
def teapot(models_dir) -> Scene:
    return Scene.from_obj(models_dir / "teapot.obj")


def _camera_rays(scene: Scene, n: int = 48) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = (np.array(b) for b in scene.bounds)
    c, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    return pinhole_rays(c + np.array([0.2, -0.9, 0.35]) * diag, c, [0, 0, 1], 0.7, n, n, tile=8)


def test_streaming_finds_the_per_ray_closest_hits(teapot: Scene) -> None:
    o, d = _camera_rays(teapot)
    t_ref, p_ref = teapot.intersect(o, d)
    t0, p0, _ = traverse(teapot, o, d, "per_ray")
    np.testing.assert_array_equal(p0, p_ref)
    t1, p1, _ = traverse(teapot, o, d, "streaming")
    assert (p_ref >= 0).mean() > 0.2  # the view really sees the teapot
    np.testing.assert_array_equal(t0, t_ref)
    np.testing.assert_array_equal(t1, t_ref)
    np.testing.assert_array_equal(p1, p_ref)


def test_single_ray_streams_cost_what_per_ray_traversal_costs(teapot: Scene) -> None:
    """A one-ray stream visits exactly the nodes and triangles a lone ray does (same order and culling)."""
    o, d = _camera_rays(teapot, n=16)
    for i in range(0, len(o), 17):
        _, _, a = traverse(teapot, o[i:i + 1], d[i:i + 1], "per_ray")
        _, _, b = traverse(teapot, o[i:i + 1], d[i:i + 1], "streaming")
        for k in ("node_fetches", "triangle_fetches", "box_tests", "triangle_tests"):
            assert a[k] == b[k], (i, k, a[k], b[k])


def test_streams_share_fetches_and_cut_bytes(teapot: Scene) -> None:
    o, d = _camera_rays(teapot, n=64)
    cache = _core.CacheConfig(32768, 64, 4)
    cmp = compare_traversal(teapot, o, d, pixels=64 * 64, cache=cache, group_size=64)
    assert cmp.same_hits
    s, r = cmp.streaming, cmp.per_ray
    # Same work per ray pair tested (every ray still meets the boxes and triangles it must) ...
    assert s["triangle_tests"] <= r["triangle_tests"] * 1.5
    # ... but each node and triangle is fetched once per stream, not once per ray.
    assert s["node_fetches"] * 10 < r["node_fetches"]
    assert cmp.bytes_per_tri_pixel(s) * 4 < cmp.bytes_per_tri_pixel(r)
    assert cmp.avg_interior_stream > 10
    # Streams never hold more rays than were traced, and their bytes are counted.
    assert s["stream_bytes"] > 0 and s["interior_stream_rays"] >= s["interior_streams"]
    assert cmp.per_ray_cached is not None
    assert cmp.per_ray_cached["scene_dram_bytes"] < r["scene_dram_bytes"]


def test_reflection_rays_stream_too(teapot: Scene, models_dir) -> None:
    from sim_core.loaders import load_obj  # the tracer helper's loader gives the raw arrays

    data = load_obj(models_dir / "teapot.obj")
    o, d = _camera_rays(teapot, n=40)
    t, p = teapot.intersect(o, d)
    ro, rd = reflection_rays(data.positions, data.triangles, o, d, t, p)
    assert len(ro) == int((p >= 0).sum())
    cmp = compare_traversal(teapot, ro, rd, pixels=40 * 40)
    assert cmp.same_hits


def test_bad_rays_are_rejected(teapot: Scene) -> None:
    with pytest.raises(ValueError):
        traverse(teapot, np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError):
        traverse(teapot, np.zeros((2, 3)), np.ones((3, 3)))
    with pytest.raises(ValueError):
        traverse(teapot, np.full((1, 3), np.nan), np.ones((1, 3)))
    with pytest.raises(ValueError):
        traverse(teapot, np.zeros((1, 3)), np.ones((1, 3)), mode="sideways")
