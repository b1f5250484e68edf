"""Scene analysis and inert parameters: settings that cannot change a scene's image or power."""

from __future__ import annotations

import numpy as np
import pytest
from sim_core.loaders import load_obj

from sim_core import Camera, Light, Material, Scene, analyze, inert_parameters

LIGHT = Light(kind="point", position=(4.0, -6.0, 8.0), intensity=300.0)


def _ground(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    s = float(np.linalg.norm(hi - lo)) * 2
    z = float(lo[2])
    p = np.array([[-s, -s, z], [s, -s, z], [s, s, z], [-s, s, z]], dtype=np.float32)
    return p, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)


@pytest.fixture(scope="module")
def teapot_data(models_dir):
    return load_obj(models_dir / "teapot.obj")


def _scene(data, teapot_material: Material) -> Scene:
    lo, hi = data.positions.min(0), data.positions.max(0)
    gp, gt = _ground(lo, hi)
    n = len(data.positions)
    pos = np.vstack([data.positions, gp]).astype(np.float32)
    tris = np.vstack([data.triangles, gt + n]).astype(np.uint32)
    mids = np.concatenate([np.zeros(len(data.triangles), np.uint32), np.ones(2, np.uint32)])
    return Scene.from_arrays(pos, tris, materials=[teapot_material, Material(base_color=(0.5, 0.6, 0.5))],
                             material_ids=mids, lights=[LIGHT])


def _camera(scene: Scene) -> Camera:
    lo, hi = (np.array(b) for b in scene.bounds)
    c, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    return Camera.look_at(c + np.array([0.2, -0.45, 0.3]) * diag, c, (0, 0, 1), 0.7, 48, 32)


SPACE = {"max_depth": [0, 1, 2, 3], "env_filter": ["off", "box", "bartlett"], "mode": ["1spp", "fsaa"]}


def test_diffuse_scene_reports_refraction_settings_inert(teapot_data) -> None:
    scene = _scene(teapot_data, Material(base_color=(0.8, 0.3, 0.2), roughness=0.6))
    a = analyze(scene)
    assert not a.refraction and not a.reflection and a.shadow_bits == 1
    assert "rays_refraction" not in a.possible_counters()
    inert = inert_parameters(scene, SPACE, _camera(scene))
    assert "max_depth" in inert and "refractive" in inert["max_depth"]
    assert "env_filter" in inert
    assert "mode" not in inert  # anti-aliasing always changes a real image


def test_refractive_scene_keeps_refraction_settings(teapot_data) -> None:
    scene = _scene(teapot_data, Material(base_color=(1, 1, 1), roughness=0.6, transmission=1.0, ior=1.5))
    a = analyze(scene)
    assert a.refraction and "refraction" in a.effects and "rays_refraction" in a.possible_counters()
    inert = inert_parameters(scene, SPACE, _camera(scene))
    assert "max_depth" not in inert
    assert "env_filter" in inert  # still no environment map to filter


def test_inert_parameters_defaults_and_validation(teapot_data) -> None:
    scene = _scene(teapot_data, Material(roughness=0.6))
    # No camera given: one framing the scene's bounds is used.
    assert "max_depth" in inert_parameters(scene, {"max_depth": [0, 2]})
    single = inert_parameters(scene, {"max_depth": [2]})
    assert single == {"max_depth": "a single candidate value: nothing to choose"}
    with pytest.raises(ValueError):
        inert_parameters(scene, {"no_such_setting": [1, 2]})
    with pytest.raises(ValueError):
        inert_parameters(scene, {"max_depth": []})


def test_interactions_with_other_parameters_are_tried(teapot_data) -> None:
    """A similarity threshold does nothing at 1 spp but matters once the space offers an adaptive mode."""
    scene = _scene(teapot_data, Material(roughness=0.6))
    cam = _camera(scene)
    alone = inert_parameters(scene, {"normal_threshold_deg": [5.0, 60.0]}, cam)
    assert "normal_threshold_deg" in alone  # neither base (FSAA, 1 spp) is adaptive
    space = {"normal_threshold_deg": [5.0, 60.0], "mode": ["1spp", "undersample"]}
    with_mode = inert_parameters(scene, space, cam)
    assert "normal_threshold_deg" not in with_mode and "mode" not in with_mode
