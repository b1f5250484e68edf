"""Pinhole cameras in the world frame (Blender's: Z up; the camera looks down its local -Z, +Y up)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

Vec3 = tuple[float, float, float]


def _vec(value: Any, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return arr


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not n > 1e-12:
        raise ValueError(f"{name} must be non-zero")
    return v / n


def _check_common(vfov: float, width: int, height: int) -> None:
    if not (isinstance(vfov, int | float | np.floating) and math.isfinite(vfov) and 0 < vfov < 3.1):
        raise ValueError(f"vfov must be in (0, 3.1) radians, got {vfov!r}")
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 1 <= v <= 16384:
            raise ValueError(f"{name} must be an integer in 1..16384, got {v!r}")


@dataclass(frozen=True)
class Camera:
    """Position, orthonormal axes (right, up, forward = local -Z), vertical FOV (radians), resolution."""

    position: Vec3
    right: Vec3
    up: Vec3
    forward: Vec3
    vfov: float
    width: int
    height: int

    @classmethod
    def from_blender(cls, matrix_world: Any, vfov_radians: float, width: int, height: int) -> Camera:
        """From Blender's camera `matrix_world` (4x4, row-major): columns 0/1/2 are the local X/Y/Z axes
        in world space and column 3 the position; the camera looks down local -Z."""
        m = np.asarray(matrix_world, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ValueError(f"matrix_world must be a finite 4x4 matrix, got shape {m.shape}")
        _check_common(vfov_radians, width, height)
        x = _unit(m[:3, 0], "matrix_world X axis")
        y = _unit(m[:3, 1], "matrix_world Y axis")
        z = _unit(m[:3, 2], "matrix_world Z axis")
        if abs(float(np.dot(np.cross(x, y), z))) < 1e-3:
            raise ValueError("matrix_world axes are degenerate")
        # Remove shear/rounding so the basis is exactly orthonormal (right-handed).
        fwd = -z
        right = _unit(x - fwd * np.dot(x, fwd), "camera right axis")
        up = np.cross(right, fwd)
        return cls(
            tuple(m[:3, 3]), tuple(right), tuple(up), tuple(fwd), float(vfov_radians), int(width), int(height)
        )

    @classmethod
    def look_at(cls, eye: Any, target: Any, up: Any, vfov_radians: float, width: int, height: int) -> Camera:
        """Camera at `eye` looking at `target`, with `up` (world, e.g. (0, 0, 1)) pointing up in the image."""
        _check_common(vfov_radians, width, height)
        e, t, u = _vec(eye, "eye"), _vec(target, "target"), _vec(up, "up")
        fwd = _unit(t - e, "target - eye")
        right = np.cross(fwd, u)
        if np.linalg.norm(right) < 1e-9:
            raise ValueError("up is parallel to the viewing direction")
        right = _unit(right, "right")
        cam_up = np.cross(right, fwd)
        return cls(
            tuple(e), tuple(right), tuple(cam_up), tuple(fwd), float(vfov_radians), int(width), int(height)
        )

    def frame(self) -> np.ndarray:
        """(4, 3) float32 rows: position, right, up, forward (what the native core takes)."""
        return np.asarray([self.position, self.right, self.up, self.forward], dtype=np.float32)

    def with_resolution(self, width: int, height: int) -> Camera:
        _check_common(self.vfov, width, height)
        return Camera(self.position, self.right, self.up, self.forward, self.vfov, int(width), int(height))

    def shifted(self, dx: float) -> Camera:
        """The same camera moved by dx along its right axis (a stereo eye)."""
        p = np.asarray(self.position) + np.asarray(self.right) * dx
        return Camera(tuple(p), self.right, self.up, self.forward, self.vfov, self.width, self.height)

    def matrix_world(self) -> np.ndarray:
        """Blender-style 4x4 world matrix of this camera."""
        m = np.eye(4)
        m[:3, 0] = self.right
        m[:3, 1] = self.up
        m[:3, 2] = -np.asarray(self.forward)
        m[:3, 3] = self.position
        return m

    def primary_rays(self) -> tuple[np.ndarray, np.ndarray]:
        """(H*W, 3) float32 origins and unit directions through pixel centres, row 0 at the top."""
        th = math.tan(self.vfov / 2)
        aspect = self.width / self.height
        ys, xs = np.mgrid[0 : self.height, 0 : self.width]
        sx = (2 * (xs + 0.5) / self.width - 1) * th * aspect
        sy = (1 - 2 * (ys + 0.5) / self.height) * th
        d = (
            np.asarray(self.forward)
            + sx[..., None] * np.asarray(self.right)
            + sy[..., None] * np.asarray(self.up)
        )
        d = d.reshape(-1, 3)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(np.asarray(self.position), d.shape)
        return o.astype(np.float32), d.astype(np.float32)
