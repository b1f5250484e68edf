"""Cycles as the reference (tests/cycles_reference.py): each Blender light type lights a diffuse plane (and
a cube's shadow) as brightly in the simulator as in a Cycles render of the same light, and a bundled HDRI
world with strength and rotation looks the same. Cycles renders live here (32x32 pixels, 64 samples:
about two seconds for all cases); bench/bench_light_units.py prints the comparison at a higher
resolution and sample count."""

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
