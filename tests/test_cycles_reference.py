"""Cycles as the reference (tests/cycles_reference.py): each Blender light type lights a diffuse plane (and
a cube's shadow) as brightly in the simulator as in a Cycles render of the same light, a bundled HDRI
world with strength and rotation looks the same and lights the plane as brightly. Cycles renders live
here (32x32 pixels, 64 samples: about two seconds for all cases); bench/bench_light_units.py prints the
comparison at a higher resolution and sample count."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.blender


@pytest.fixture(scope="module")
def light_scenes():
    pytest.importorskip("bpy")
    import cycles_reference

    return cycles_reference


@pytest.mark.parametrize("case", [
    "point", "point_radius", "spot", "spot_blend", "sun", "sun_angle", "area_square", "area_rectangle",
    "area_disk", "area_ellipse",
])
def test_mean_brightness_matches_cycles(light_scenes, case: str) -> None:
    cycles, _ = light_scenes.cycles_mean(case, size=32, samples=64)
    simulated, _ = light_scenes.simulator_mean(case, size=32)
    assert cycles > 0.05
    assert simulated == pytest.approx(cycles, rel=0.03)


@pytest.mark.parametrize("strength,rotation", [(1.0, 0.0), (1.5, 1.2)])
def test_hdri_world_matches_cycles(light_scenes, strength: float, rotation: float) -> None:
    """Blender's equirectangular mapping, strength and Mapping rotation: the same background as Cycles."""
    import numpy as np

    cycles = light_scenes.cycles_world(strength, rotation)
    simulated = light_scenes.simulator_world(strength, rotation)
    assert float(simulated.mean()) == pytest.approx(float(cycles.mean()), rel=0.02)
    assert np.corrcoef(cycles.ravel(), simulated.ravel())[0, 1] > 0.97


@pytest.mark.parametrize("rotation", [0.0, 2.0])
def test_hdri_lights_the_plane_like_cycles(light_scenes, rotation: float) -> None:
    """The world as the only light: forest.exr's sky (SH irradiance occluded by AO rays) and its sun (an
    environment light with shadow rays: the cube's shadow) light the diffuse plane as brightly as Cycles'
    importance-sampled world does."""
    cycles, _ = light_scenes.cycles_world_lit(0.5, rotation, size=32, samples=64)
    simulated, _ = light_scenes.simulator_world_lit(0.5, rotation, size=32)
    assert cycles > 0.2
    assert simulated == pytest.approx(cycles, rel=0.04)


def test_artist_scene_close_to_cycles(light_scenes) -> None:
    """Textured cube, glossy sphere, rough metal floor (roughness 0.45), area + point + sun lights and a
    bundled HDRI: mean display luminance within 10 % and 1-SSIM under 0.12 of Cycles' (issue 12's targets
    are 10 % and 0.10 at 320x180; bench/bench_light_units.py prints that)."""
    cycles = light_scenes.cycles_artist((96, 54), samples=32)
    simulated = light_scenes.simulator_artist((96, 54))
    ratio, dissimilarity = light_scenes.fidelity(cycles, simulated.image)
    assert ratio == pytest.approx(1.0, abs=0.10)
    assert dissimilarity < 0.12
    c = simulated.counters
    assert c["texture_fetches"] > 0 and c["area_light_evals"] > 0 and c["env_sh_evals"] > 0
