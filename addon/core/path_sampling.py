"""Camera-path maths shared by recording, export and playback (pure: no bpy)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from service import camera_path

#: Blender's 3D viewport treats its lens as if the sensor were 72 mm wide (twice a 36 mm camera sensor).
VIEWPORT_SENSOR_MM = 72.0


def matrix_tuple(matrix: Sequence[Sequence[float]]) -> tuple[tuple[float, ...], ...]:
    """Copy any 4x4 row-major matrix (mathutils.Matrix, list, ndarray) into nested float tuples."""
    rows = tuple(tuple(float(v) for v in row) for row in matrix)
    if len(rows) != 4 or any(len(r) != 4 for r in rows):
        raise ValueError("expected a 4x4 matrix")
    return rows


def vertical_fov(
    lens_mm: float,
    sensor_width_mm: float,
    sensor_height_mm: float,
    sensor_fit: str,
    width: int,
    height: int,
    pixel_aspect_x: float = 1.0,
    pixel_aspect_y: float = 1.0,
) -> float:
    """Vertical field of view (radians) of a perspective Blender camera for a render size.

    Follows Blender's sensor-fit rule: AUTO fits the sensor width to the larger image side,
    HORIZONTAL fits the width to the image width, VERTICAL fits the sensor height to the image height.
    """
    if lens_mm <= 0 or not math.isfinite(lens_mm):
        raise ValueError(f"lens must be a positive focal length in mm, got {lens_mm}")
    if width <= 0 or height <= 0:
        raise ValueError(f"resolution must be positive, got {width}x{height}")
    aspect = (width * pixel_aspect_x) / (height * pixel_aspect_y)  # display width / height
    if sensor_fit == "AUTO":
        if aspect >= 1.0:
            half_w = math.atan(sensor_width_mm / (2.0 * lens_mm))
            return 2.0 * math.atan(math.tan(half_w) / aspect)
        return 2.0 * math.atan(sensor_width_mm / (2.0 * lens_mm))
    if sensor_fit == "HORIZONTAL":
        half_w = math.atan(sensor_width_mm / (2.0 * lens_mm))
        return 2.0 * math.atan(math.tan(half_w) / aspect)
    if sensor_fit == "VERTICAL":
        return 2.0 * math.atan(sensor_height_mm / (2.0 * lens_mm))
    raise ValueError(f"unknown sensor_fit {sensor_fit!r}")


def camera_lens_from_viewport(viewport_lens_mm: float, sensor_width_mm: float) -> float:
    """Lens of a camera with `sensor_width_mm` that frames like the viewport (viewport sensor is 72 mm)."""
    if viewport_lens_mm <= 0 or sensor_width_mm <= 0:
        raise ValueError("lens and sensor width must be positive")
    return viewport_lens_mm * sensor_width_mm / VIEWPORT_SENSOR_MM


def frame_times(frame_start: int, frame_end: int, fps: float, step: int = 1) -> list[tuple[int, float]]:
    """(frame, time in seconds from the first frame) over an inclusive frame range."""
    if frame_end < frame_start:
        raise ValueError(f"empty frame range {frame_start}..{frame_end}")
    if fps <= 0 or not math.isfinite(fps):
        raise ValueError(f"fps must be positive, got {fps}")
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    return [(f, (f - frame_start) / fps) for f in range(frame_start, frame_end + 1, step)]


def build_path(samples: Sequence[tuple[float, Sequence[Sequence[float]], float, tuple[int, int]]],
               fps: float) -> camera_path.CameraPath:
    """A validated CameraPath (the shared format module) from (time, matrix_world, vfov, resolution)."""
    if not samples:
        raise ValueError("a camera path needs at least one sample")
    frames = tuple(camera_path.CameraFrame(float(t), np.asarray(m, dtype=np.float64), float(v),
                                           (int(r[0]), int(r[1])))
                   for t, m, v, r in samples)
    return camera_path.CameraPath(frames, float(fps))


def max_matrix_deviation(a: camera_path.CameraPath, b: camera_path.CameraPath) -> float:
    """Largest absolute element difference between two equally long paths' matrices."""
    if len(a) != len(b):
        raise ValueError(f"paths differ in length: {len(a)} vs {len(b)}")
    return max(float(np.abs(fa.matrix_world - fb.matrix_world).max())
               for fa, fb in zip(a.frames, b.frames, strict=True))
