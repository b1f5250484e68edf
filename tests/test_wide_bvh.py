"""The renderer's 4-wide BVH against the binary reference walk, and its counters against the documented
traffic model (ARCHITECTURE.md, counter meanings): a node visit is one 128-byte 4-wide node, a triangle test
one 48-byte record, every fetch goes through the tile's cache model at base + index * record size, and
shadow / AO rays are any-hit queries that stop at their first hit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sim_core.render import ANY_HIT_KINDS, RAY_KINDS
from tracer_scenes import effects_camera, effects_scene, teapot_camera, teapot_on_plane

from sim_core import Camera, Light, Material, RenderSettings, Scene, render

# Every ray kind: FSAA primary rays, soft shadows of two lights, AO, mirror, glossy and glass bounces.
ALL_RAYS = RenderSettings(mode="fsaa", block=2, shadow_samples=4, ao_samples=3, max_depth=3)


@pytest.fixture(scope="module")
def effects():
    return effects_scene()


@pytest.fixture(scope="module")
def teapot():
    return teapot_on_plane()


def _replay(scene: Scene, rays, bvh_width: int) -> dict[str, int]:
    """What the traversal reports for every logged ray, each with its own query (any hit for shadow/AO)."""
    total = {"node_fetches": 0, "node_bytes": 0, "triangle_tests": 0, "comparisons": 0}
    for kind in RAY_KINDS:
        m = rays.of_kind(kind)
        if not m.any():
            continue
        query = "any" if kind in ANY_HIT_KINDS else "closest"
        s = scene.native.traversal_stats(rays.origins[m], rays.directions[m], query, bvh_width, rays.tmax[m])
        for k in total:
            total[k] += s[k]
    return total


@pytest.mark.parametrize("which", ["effects", "teapot"])
def test_wide_walk_renders_the_binary_walks_images(which, effects, teapot):
    """Same closest hits (t and triangle: ties at exactly equal t go to the lower triangle index in both
    walks) and the same occlusion answers, hence bit-identical images, AOVs and ray counts."""
    scene, cam = (effects, effects_camera(64, 36)) if which == "effects" else (teapot, teapot_camera(48, 36))
    wide = render(scene, cam, ALL_RAYS, threads=2)
    binary = render(scene, cam, ALL_RAYS, threads=2, bvh_width=2)
    np.testing.assert_array_equal(wide.image, binary.image)
    for aov in ("depth", "normal", "object_id", "position"):
        np.testing.assert_array_equal(wide.aovs[aov], binary.aovs[aov])
    for k in ("rays_primary", "rays_shadow", "rays_reflection", "rays_refraction", "rays_ao", "rays_glossy",
              "shading_evals", "env_lookups"):
        assert wide.counters[k] == binary.counters[k], k
    if which == "effects":
        assert all(wide.counters[f"rays_{k}"] > 0 for k in RAY_KINDS)
    # The wide tree needs far fewer node steps (each tests four boxes) for a few more triangle tests.
    assert wide.counters["bvh_node_visits"] * 3 < binary.counters["bvh_node_visits"]
    assert wide.counters["triangle_tests"] < 2 * binary.counters["triangle_tests"]


def test_exact_ties_are_resolved_the_same_way_by_both_walks():
    """A quad stacked eight times with different objects (z-fighting, as where the chess board's squares
    lie on its slab): every ray that hits it meets eight triangles at exactly the same t, spread over
    several leaves the two walks visit in different orders (equal boxes: the binary walk takes the first
    child, the 4-wide one the last); both return the lowest (leaf-order) index."""
    q = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    copies = 8
    pos = np.vstack([q] * copies).astype(np.float32)
    tri = np.vstack([np.array([[0, 1, 2], [0, 2, 3]]) + 4 * k for k in range(copies)])
    ids = np.repeat(np.arange(copies), 2)
    mats = [Material(base_color=(0.1 + 0.1 * k, 0.5, 0.9 - 0.1 * k)) for k in range(copies)]
    scene = Scene.from_arrays(pos, tri, material_ids=ids, object_ids=ids, materials=mats,
                              lights=[Light(kind="point", position=(0.0, 0.0, 3.0), intensity=20.0)])
    cam = Camera.look_at((0.3, -2.0, 2.5), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.9, 40, 30)
    wide = render(scene, cam, RenderSettings(), threads=1)
    binary = render(scene, cam, RenderSettings(), threads=1, bvh_width=2)
    assert (wide.aovs["object_id"] >= 0).sum() > 200
    np.testing.assert_array_equal(wide.image, binary.image)
    np.testing.assert_array_equal(wide.aovs["object_id"], binary.aovs["object_id"])


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 300), duplicates=st.integers(0, 40))
def test_both_walks_return_the_same_hits_on_random_soups(seed: int, n: int, duplicates: int):
    """Random triangle soups, some triangles duplicated exactly (ties at equal t), random rays and
    segments: the 4-wide and the binary walk agree on t, triangle and occlusion for every ray."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(n, 1, 3)) * 3
    pos = (centres + rng.normal(size=(n, 3, 3)) * rng.uniform(0.05, 1.5, size=(n, 1, 1))).reshape(-1, 3)
    tri = np.arange(3 * n).reshape(n, 3)
    # Up to 8 copies of a few triangles: exact ties, in leaves of their own (equal centroids split by count).
    copied = tri[rng.integers(0, n, duplicates // 8 + 1)]
    tri = np.vstack([tri, np.repeat(copied, duplicates % 8 + 1, axis=0)])
    scene = Scene.from_arrays(pos.astype(np.float32), tri)
    m = 2000
    o = (rng.normal(size=(m, 3)) * 5).astype(np.float32)
    d = (rng.normal(size=(m, 3)) - o * rng.uniform(0, 0.3, size=(m, 1))).astype(np.float32)
    tmax = (rng.uniform(0, 10, m)).astype(np.float32)
    t4, p4 = scene.native.intersect(o, d, 1, 4)
    t2, p2 = scene.native.intersect(o, d, 1, 2)
    np.testing.assert_array_equal(t4, t2)
    np.testing.assert_array_equal(p4, p2)
    occluded = [scene.native.occluded(o, d, 1, width, tmax) for width in (4, 2)]
    np.testing.assert_array_equal(*occluded)


@pytest.mark.parametrize("bvh_width,node_bytes", [(4, 128), (2, 32)])
def test_counters_follow_the_traffic_model(effects, bvh_width, node_bytes):
    """Node visits, triangle tests and comparisons are exactly what the traversal reports for the render's
    own rays; with 16-byte lines (node records and 48-byte triangle records line-aligned) every node fetch
    is node_bytes / 16 line accesses and every triangle fetch 3; tiles add up to the frame."""
    cam = effects_camera(48, 32)
    r = render(effects, cam, ALL_RAYS, threads=2, cache=(4096, 16, 4), bvh_width=bvh_width, log_rays=True)
    c = r.counters
    assert r.rays is not None and len(r.rays.kind) == c["rays_total"]
    for kind in RAY_KINDS:
        assert int(r.rays.of_kind(kind).sum()) == c[f"rays_{kind}"]
    replay = _replay(effects, r.rays, bvh_width)
    assert replay["node_fetches"] == c["bvh_node_visits"]
    assert replay["node_bytes"] == node_bytes * c["bvh_node_visits"]
    assert replay["triangle_tests"] == c["triangle_tests"]
    assert replay["comparisons"] == c["closest_hit_comparisons"] == r.comparator_histogram.sum()
    assert c["cache_accesses"] == node_bytes // 16 * c["bvh_node_visits"] + 3 * c["triangle_tests"]
    assert c["dram_bytes_read"] == 16 * c["cache_misses"]
    for k in ("rays_total", "bvh_node_visits", "triangle_tests", "cache_misses"):
        assert sum(t[k] for t in r.tile_stats) == c[k], k
    # Without a cache every fetch is one DRAM read in 32-byte bursts: 128 (or 32) bytes per node, 64 per
    # 48-byte triangle record.
    off = render(effects, cam, ALL_RAYS, threads=2, cache=(0, 64, 4), bvh_width=bvh_width)
    assert off.counters["bvh_node_visits"] == c["bvh_node_visits"]
    assert off.counters["cache_misses"] == c["bvh_node_visits"] + c["triangle_tests"]
    assert off.counters["dram_bytes_read"] == node_bytes * c["bvh_node_visits"] + 64 * c["triangle_tests"]


def test_any_hit_rays_stop_at_their_first_hit(effects):
    """Per shadow / AO ray: an occluded ray fetches no more than the closest-hit walk of the same ray would,
    and an unoccluded one exactly as much (it must rule out every box it enters)."""
    r = render(effects, effects_camera(32, 18), ALL_RAYS, threads=2, log_rays=True)
    rays = r.rays
    idx = np.flatnonzero(rays.of_kind("shadow") | rays.of_kind("ao"))
    rng = np.random.default_rng(0)
    fewer = 0
    for i in rng.choice(idx, size=min(400, idx.size), replace=False):
        o, d, tm = rays.origins[i:i + 1], rays.directions[i:i + 1], rays.tmax[i:i + 1]
        a = effects.native.traversal_stats(o, d, "any", 4, tm)
        b = effects.native.traversal_stats(o, d, "closest", 4, tm)
        assert a["comparisons"] == 0
        assert a["hits"] == b["hits"]
        if a["hits"]:
            assert a["node_fetches"] <= b["node_fetches"] and a["triangle_tests"] <= b["triangle_tests"]
            fewer += a["node_fetches"] + a["triangle_tests"] < b["node_fetches"] + b["triangle_tests"]
        else:
            assert (a["node_fetches"], a["triangle_tests"]) == (b["node_fetches"], b["triangle_tests"])
    assert fewer > 10  # stopping early really saves fetches


def test_unoccluded_shadow_rays_cost_what_closest_hit_rays_cost():
    """A lit ground grid with nothing above it: no shadow ray is blocked, so the render's traversal counters
    equal a closest-hit walk of every one of its rays."""
    g = np.linspace(-4, 4, 9)
    gx, gy = np.meshgrid(g, g)
    pos = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1).astype(np.float32)
    quads = [(j * 9 + i, j * 9 + i + 1, j * 9 + i + 10, j * 9 + i + 9) for j in range(8) for i in range(8)]
    tri = np.array([(a, b, c) for a, b, c, _ in quads] + [(a, c, d) for a, _, c, d in quads])
    scene = Scene.from_arrays(pos, tri, lights=[Light(kind="point", position=(0.5, 0.3, 5.0), intensity=50.0,
                                                      radius=0.4)])
    cam = Camera.look_at((0.0, -3.0, 5.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.8, 40, 30)
    r = render(scene, cam, RenderSettings(shadow_samples=8, max_depth=0), threads=2, log_rays=True)
    c = r.counters
    assert c["rays_shadow"] > 1000
    shadow = r.rays.of_kind("shadow")
    assert not scene.occluded(r.rays.origins[shadow], r.rays.directions[shadow], r.rays.tmax[shadow]).any()
    as_closest = scene.native.traversal_stats(r.rays.origins, r.rays.directions, "closest", 4, r.rays.tmax)
    assert as_closest["node_fetches"] == c["bvh_node_visits"]
    assert as_closest["triangle_tests"] == c["triangle_tests"]


def test_trace_options_are_validated(teapot):
    cam = teapot_camera(8, 8)
    for bad in (3, 8, True, "4"):
        with pytest.raises(ValueError, match="bvh_width"):
            render(teapot, cam, bvh_width=bad)
    with pytest.raises(ValueError, match="log_rays"):
        render(teapot, cam, log_rays=1)
    assert render(teapot, cam).rays is None
