"""Energy model on real renders: scaling invariants, adaptive savings, blocks a render cannot use."""

from __future__ import annotations

import numpy as np
import pytest
from sim_core.loaders import load_obj

import sim_core
from sim_core import Camera, Light, Material, RenderSettings, Scene, load_profile, price, render

MOBILE = load_profile("mobile")
TI_BLOCKS = ("traversal", "intersection", "comparator", "cache")


@pytest.fixture(scope="module")
def teapot_data(models_dir):
    return load_obj(models_dir / "teapot.obj")


@pytest.fixture(scope="module")
def teapot(teapot_data) -> Scene:
    light = Light(kind="point", position=(4.0, -6.0, 8.0), intensity=300.0)
    return Scene.from_arrays(teapot_data.positions, teapot_data.triangles, lights=[light])


def _camera(scene: Scene, w: int, h: int, dist: float = 0.9) -> Camera:
    lo, hi = (np.array(b) for b in scene.bounds)
    c, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    return Camera.look_at(c + np.array([0.2, -1.0, 0.35]) * diag * dist, c, (0, 0, 1), 0.7, w, h)


def _ti(report) -> float:
    return sum(report.energy_j[b] for b in TI_BLOCKS)


def test_dynamic_energy_of_1spp_scales_with_pixel_count(teapot: Scene) -> None:
    settings = RenderSettings(mode="1spp")
    small = price(render(teapot, _camera(teapot, 512, 256), settings, cache=MOBILE.cache), MOBILE, 30)
    large = price(render(teapot, _camera(teapot, 1024, 512), settings, cache=MOBILE.cache), MOBILE, 30)
    assert large.dynamic_energy_j / small.dynamic_energy_j == pytest.approx(4.0, rel=0.10)
    # Every per-sample block scales exactly with the pixels; only DRAM (per-tile working sets) lags.
    per_sample = ("raygen", "shading", "traversal", "intersection", "cache", "tile_buffer", "framebuffer_dma")
    for block in per_sample:
        assert large.energy_j[block] / small.energy_j[block] == pytest.approx(4.0, rel=0.02), block
    assert large.energy_j["dram"] < 4.0 * small.energy_j["dram"]


@pytest.mark.parametrize("block", [2, 4])
def test_undersampling_lowers_ti_energy_in_proportion_to_rays_not_traced(teapot: Scene, block: int) -> None:
    cam = _camera(teapot, 320, 240, dist=0.5)  # the view is filled with geometry
    full = render(teapot, cam, RenderSettings(mode="1spp"), cache=MOBILE.cache)
    under = render(teapot, cam, RenderSettings(mode="undersample", block=block), cache=MOBILE.cache)
    ef, eu = price(full, MOBILE, 30), price(under, MOBILE, 30)
    rays_cut = 1 - under.counters["rays_total"] / full.counters["rays_total"]
    energy_cut = 1 - _ti(eu) / _ti(ef)
    assert rays_cut > 0.3
    assert energy_cut == pytest.approx(rays_cut, rel=0.10)
    # The adaptive kernels are priced, and only when adaptive sampling runs.
    assert ef.energy_j["similarity"] == ef.energy_j["interpolation"] == 0.0
    assert eu.energy_j["similarity"] > 0 and eu.energy_j["interpolation"] > 0


def test_blocks_a_render_cannot_use_cost_exactly_zero(teapot: Scene) -> None:
    r = render(teapot, _camera(teapot, 96, 64), RenderSettings(mode="1spp", ao_samples=0), cache=MOBILE.cache)
    rep = price(r, MOBILE, 30, scene=teapot)
    c = r.counters
    # Diffuse teapot, one point light, constant environment, mono: no secondary rays, no filtering,
    # no reprojection, no G-buffer prefetch, no adaptive kernels.
    for k in ("rays_reflection", "rays_refraction", "rays_glossy", "rays_ao", "env_filtered_lookups",
              "reprojections", "gbuffer_prefetch_bytes", "similarity_checks", "interpolations"):
        assert c[k] == 0, k
    for b in ("similarity", "interpolation", "reprojection", "gbuffer_prefetch", "env_filter"):
        assert rep.energy_j[b] == 0.0 and rep.cycles[b] == 0.0, b
    assert c["rays_shadow"] > 0  # the one light does cost shadow rays
    # Power at the target frame rate (this small frame meets its deadline), and the comparator histogram
    # accounts for every comparison.
    assert rep.deadline_met and rep.achieved_fps == 30
    assert rep.power_w == pytest.approx(MOBILE.static_power_w + rep.dynamic_energy_j * 30, rel=1e-12)
    assert int(r.comparator_histogram.sum()) == c["closest_hit_comparisons"] == rep.comparator.comparisons


def test_stereo_prices_reprojection_and_gbuffer_prefetch(teapot: Scene) -> None:
    cam = _camera(teapot, 128, 96)
    st = sim_core.render_stereo(teapot, cam, 0.06, RenderSettings(mode="1spp"), cache=MOBILE.cache)
    right = price(st.right, MOBILE, 30)
    left = price(st.left, MOBILE, 30)
    assert right.energy_j["reprojection"] > 0 and right.energy_j["gbuffer_prefetch"] > 0
    assert left.energy_j["reprojection"] == 0.0
    assert st.right.counters["rays_total"] < st.left.counters["rays_total"]  # reused pixels are not traced


def test_cache_geometry_comes_from_the_profile(teapot: Scene) -> None:
    cam = _camera(teapot, 128, 96)
    small = render(teapot, cam, RenderSettings(), cache=sim_core._core.CacheConfig(1024, 64, 2))
    big = render(teapot, cam, RenderSettings(), cache=MOBILE.cache)
    assert small.counters["bvh_node_visits"] == big.counters["bvh_node_visits"]
    assert small.counters["cache_misses"] > big.counters["cache_misses"]
    assert price(small, MOBILE, 30).energy_j["dram"] > price(big, MOBILE, 30).energy_j["dram"]


def test_glossy_environment_filter_is_priced_by_order(teapot_data) -> None:
    env = np.ones((32, 64, 3), dtype=np.float32)
    env[:16] *= 3.0
    metal = Material(base_color=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.3)
    scene = Scene.from_arrays(teapot_data.positions, teapot_data.triangles, materials=[metal],
                              material_ids=np.zeros(len(teapot_data.triangles), np.uint32), environment=env)
    cam = _camera(scene, 96, 64)
    reps = {}
    for f in ("off", "box", "bartlett"):
        r = render(scene, cam, RenderSettings(env_filter=f, max_depth=1), cache=MOBILE.cache)
        reps[f] = (r, price(r, MOBILE, 30, scene=scene))
    assert reps["off"][0].counters["env_filtered_lookups"] == 0
    n_box = reps["box"][0].counters["env_filtered_lookups"]
    assert n_box > 0 and n_box == reps["bartlett"][0].counters["env_filtered_lookups"]
    assert reps["bartlett"][1].energy_j["env_filter"] > reps["box"][1].energy_j["env_filter"]
