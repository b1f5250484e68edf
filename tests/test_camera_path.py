"""Camera-path JSON: round trip, alternative pose encodings, validation."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from service.camera_path import CameraFrame, CameraPath


def _doc() -> dict:
    return {"version": 1, "fps": 24.0, "frames": [
        {"time": 0.0, "matrix_world": np.eye(4).tolist(), "vfov": 0.6911, "resolution": [1920, 1080]},
        {"time": 0.5, "position": [1, 2, 3], "direction": [0, 1, 0], "vfov": 0.5, "resolution": [64, 48]},
        {"time": 1.0, "position": [0, 0, 1],
         "rotation_quaternion": [math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0],
         "vfov": 0.5, "resolution": [64, 48]},
    ]}


def test_roundtrip_and_poses(tmp_path) -> None:
    p = CameraPath.from_dict(_doc())
    assert len(p) == 3 and p.fps == 24.0
    assert np.allclose(p.frames[0].direction, [0, 0, -1])  # identity camera looks down -Z
    assert np.allclose(p.frames[1].direction, [0, 1, 0]) and np.allclose(p.frames[1].position, [1, 2, 3])
    # Blender: rotating the camera 90 degrees about X makes it look along +Y
    assert np.allclose(p.frames[2].direction, [0, 1, 0])
    assert np.allclose(p.frames[1].matrix_world[:3, 1], [0, 0, 1])  # up stays world +Z
    f = tmp_path / "path.json"
    p.save(f)
    q = CameraPath.load(f)
    assert q.to_dict() == p.to_dict()
    assert json.loads(f.read_text())["frames"][1]["matrix_world"][1][3] == 2.0
    lo, hi = q.bounds()
    assert np.allclose(lo, [0, 0, 0]) and np.allclose(hi, [1, 2, 3])


@pytest.mark.parametrize("mutate,msg", [
    (lambda d: d.update(version=2), "version"),
    (lambda d: d.update(frames=[]), "at least one"),
    (lambda d: d["frames"][0].update(vfov=4.0), "vfov"),
    (lambda d: d["frames"][0].update(resolution=[0, 10]), "resolution"),
    (lambda d: d["frames"][0].update(matrix_world=[[1, 0], [0, 1]]), "4x4"),
    (lambda d: d["frames"][0]["matrix_world"][0].__setitem__(3, float("nan")), "finite"),
    (lambda d: d["frames"][1].update(time=-1.0), "non-decreasing"),
    (lambda d: d["frames"][1].update(direction=[0, 0, 0]), "non-zero"),
    (lambda d: d["frames"][1].pop("time"), "time"),
    (lambda d: d.update(fps=-3), "fps"),
])
def test_validation(mutate, msg: str) -> None:
    d = _doc()
    mutate(d)
    with pytest.raises(ValueError, match=msg):
        CameraPath.from_dict(d)


def test_huge_orientations_do_not_overflow() -> None:
    d = _doc()
    d["frames"][1]["direction"] = [0, 1e308, 0]
    d["frames"][2]["rotation_quaternion"] = [1e308, 1e308, 0, 0]
    p = CameraPath.from_dict(d)
    assert np.allclose(p.frames[1].direction, [0, 1, 0]) and np.allclose(p.frames[2].direction, [0, 1, 0])


def test_not_json_and_from_positions() -> None:
    with pytest.raises(ValueError, match="JSON"):
        CameraPath.from_json("{nope")
    p = CameraPath.from_positions([[0, 0, 0], [1, 0, 0]], [[1, 0, 0], [0, 0, -1]], resolution=(32, 24))
    assert np.allclose(p.directions(), [[1, 0, 0], [0, 0, -1]])
    assert p.frames[1].time == pytest.approx(1 / 30)
    assert isinstance(p.frames[0], CameraFrame) and p.frames[0].aspect == pytest.approx(32 / 24)
