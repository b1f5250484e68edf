"""Camera-path JSON: read, write and validate the recorded path the optimiser refines its octree along.

Format (version 1; written by the add-on and the scene generators)::

    {"version": 1, "fps": 30.0,
     "frames": [{"time": 0.0,
                 "matrix_world": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]],
                 "vfov": 0.6911, "resolution": [1920, 1080]}]}

``matrix_world`` is Blender's camera world matrix (row-major; the camera looks down its local -Z with
+Y up), ``vfov`` the vertical field of view in radians, ``time`` in seconds (non-decreasing). Instead of
``matrix_world`` a frame may give ``position`` plus either ``rotation_quaternion`` ([w, x, y, z], Blender's
order) or ``direction`` (and optional ``up``, default world +Z); the reader turns those into a matrix and
the writer always writes ``matrix_world``. Camera maths and the camera limits every layer shares come
from :mod:`service.store.camera`. Pure stdlib + numpy: the add-on bundles this module (with the store
package).
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .options import FPS_MAX, FPS_MIN
from .store import camera

PATH_VERSION = 1


def _finite(a: np.ndarray, what: str) -> np.ndarray:
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} must be finite")
    return a


@dataclass(frozen=True)
class CameraFrame:
    """One recorded camera: time (s), Blender world matrix (4x4), vertical fov (rad), resolution."""

    time: float
    matrix_world: np.ndarray
    vfov: float
    resolution: tuple[int, int]

    def __post_init__(self) -> None:
        m = np.asarray(self.matrix_world, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError(f"matrix_world must be 4x4, got shape {m.shape}")
        _finite(m, "matrix_world")
        axes = camera.check_axes(m)
        camera.check_position(m[:3, 3], "matrix_world position")
        with np.errstate(over="ignore", under="ignore"):  # 1e300-long axes: inf, i.e. not unit
            unit = np.abs(np.linalg.norm(m[:3, :3], axis=0) - 1.0).max() <= 1e-6
        if not unit:
            # A camera's scale means nothing: scaled (or hugely or tinily scaled) axes are stored with unit
            # length, so every later use is safe; unit axes stay exactly as given.
            m = m.copy()
            m[:3, :3] = axes
        object.__setattr__(self, "matrix_world", m)
        if not math.isfinite(self.time):
            raise ValueError("time must be finite")
        camera.check_fov(self.vfov, "vfov")
        if len(self.resolution) != 2:
            raise ValueError(f"resolution must be two integers, got {self.resolution!r}")
        object.__setattr__(self, "resolution", camera.check_resolution(*self.resolution))

    @property
    def position(self) -> np.ndarray:
        return self.matrix_world[:3, 3].copy()

    @property
    def direction(self) -> np.ndarray:
        """Unit view direction (the camera's local -Z in world space)."""
        return camera.forward_of(self.matrix_world)

    @property
    def aspect(self) -> float:
        return self.resolution[0] / self.resolution[1]

    def to_dict(self) -> dict[str, Any]:
        return {"time": self.time, "matrix_world": self.matrix_world.tolist(), "vfov": self.vfov,
                "resolution": list(self.resolution)}

    @staticmethod
    def from_dict(d: dict[str, Any], index: int = 0) -> CameraFrame:
        if not isinstance(d, dict):
            raise ValueError(f"frame {index} must be an object")
        try:
            if "matrix_world" in d:
                m = np.asarray(d["matrix_world"], dtype=np.float64)
            elif "position" in d:
                pos = np.asarray(d["position"], dtype=np.float64).reshape(3)
                pos = _finite(pos, f"frame {index} position")
                if "rotation_quaternion" in d:
                    q = np.asarray(d["rotation_quaternion"], dtype=np.float64).reshape(4)
                    m = camera.quaternion_matrix(pos, _finite(q, f"frame {index} rotation_quaternion"))
                elif "direction" in d:
                    f = np.asarray(d["direction"], dtype=np.float64).reshape(3)
                    up = np.asarray(d.get("up", [0.0, 0.0, 1.0]), dtype=np.float64).reshape(3)
                    m = camera.look_matrix(pos, _finite(f, "direction"), _finite(up, "up"))
                else:
                    raise ValueError(f"frame {index}: position needs rotation_quaternion or direction")
            else:
                raise ValueError(f"frame {index}: needs matrix_world or position")
            return CameraFrame(float(d["time"]), m, float(d["vfov"]),
                               tuple(d["resolution"]))  # type: ignore[arg-type]
        except KeyError as exc:
            raise ValueError(f"frame {index}: missing field {exc}") from exc
        except (TypeError, ValueError) as exc:
            raise ValueError(f"frame {index}: {exc}") from exc


@dataclass(frozen=True)
class CameraPath:
    """A recorded camera path (at least one frame, times non-decreasing)."""

    frames: tuple[CameraFrame, ...]
    fps: float = 30.0

    def __post_init__(self) -> None:
        frames = tuple(self.frames)
        if not frames:
            raise ValueError("a camera path needs at least one frame")
        if not (math.isfinite(self.fps) and FPS_MIN <= self.fps <= FPS_MAX):
            raise ValueError(f"fps must be in [{FPS_MIN}, {FPS_MAX}]")
        times = [f.time for f in frames]
        if any(b < a for a, b in itertools.pairwise(times)):
            raise ValueError("frame times must be non-decreasing")
        object.__setattr__(self, "frames", frames)

    def __len__(self) -> int:
        return len(self.frames)

    def positions(self) -> np.ndarray:
        return np.stack([f.position for f in self.frames])

    def directions(self) -> np.ndarray:
        return np.stack([f.direction for f in self.frames])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        p = self.positions()
        return p.min(axis=0), p.max(axis=0)

    def to_dict(self) -> dict[str, Any]:
        return {"version": PATH_VERSION, "fps": self.fps, "frames": [f.to_dict() for f in self.frames]}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), allow_nan=False)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> CameraPath:
        if not isinstance(d, dict):
            raise ValueError("camera path must be a JSON object")
        if d.get("version") != PATH_VERSION:
            raise ValueError(f"unsupported camera path version {d.get('version')!r}")
        frames = d.get("frames")
        if not isinstance(frames, list):
            raise ValueError("camera path needs a 'frames' list")
        try:
            fps = float(d.get("fps", 30.0))
        except (TypeError, ValueError) as exc:
            raise ValueError("fps must be a number") from exc
        return CameraPath(tuple(CameraFrame.from_dict(f, i) for i, f in enumerate(frames)), fps)

    @staticmethod
    def from_json(text: str | bytes) -> CameraPath:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"camera path is not valid JSON: {exc}") from exc
        return CameraPath.from_dict(d)

    @staticmethod
    def load(path: str | Path) -> CameraPath:
        return CameraPath.from_json(Path(path).read_text(encoding="utf-8"))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_json(), encoding="utf-8")

    @staticmethod
    def from_positions(positions: Sequence[Sequence[float]], directions: Sequence[Sequence[float]],
                       vfov: float = 0.6911, resolution: tuple[int, int] = (1920, 1080),
                       fps: float = 30.0) -> CameraPath:
        """Build a path from positions and view directions (up = world +Z, or +Y looking straight up or
        down), one frame per 1/fps."""
        if len(positions) != len(directions):
            raise ValueError("positions and directions differ in length")
        frames = []
        for i, (p, f) in enumerate(zip(positions, directions, strict=True)):
            pos = _finite(np.asarray(p, dtype=np.float64).reshape(3), "position")
            fd = _finite(np.asarray(f, dtype=np.float64).reshape(3), "direction")
            frames.append(CameraFrame(i / fps, camera.look_matrix(pos, fd), vfov, resolution))
        return CameraPath(tuple(frames), fps)
