"""Camera-path maths shared by recording, export and playback (pure: no bpy)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .vendored import camera_path

#: Blender's 3D viewport treats its lens as if the sensor were 72 mm wide (twice a 36 mm camera sensor).
VIEWPORT_SENSOR_MM = 72.0


def vertical_fov(
    angle_x: float,
    angle_y: float,
    sensor_fit: str,
    width: int,
    height: int,
    pixel_aspect_x: float = 1.0,
    pixel_aspect_y: float = 1.0,
) -> float:
    """Vertical field of view (radians) of a perspective Blender camera for a render size.

    ``angle_x`` / ``angle_y`` are the camera's own lens angles over the sensor width / height (Blender's
    ``Camera.angle_x`` / ``angle_y``: the lens and sensor converted once, by Blender). Follows Blender's
    sensor-fit rule: AUTO fits the sensor width to the larger image side, HORIZONTAL fits the width to
    the image width, VERTICAL fits the sensor height to the image height.
    """
    for name, angle in (("angle_x", angle_x), ("angle_y", angle_y)):
        if not (math.isfinite(angle) and 0.0 < angle < math.pi):
            raise ValueError(f"{name} must be a lens angle in (0, pi) radians, got {angle}")
    if width <= 0 or height <= 0:
        raise ValueError(f"resolution must be positive, got {width}x{height}")
    shown_w, shown_h = width * pixel_aspect_x, height * pixel_aspect_y  # the displayed image's shape
    if sensor_fit == "VERTICAL":
        return float(angle_y)
    if sensor_fit not in ("AUTO", "HORIZONTAL"):
        raise ValueError(f"unknown sensor_fit {sensor_fit!r}")
    if sensor_fit == "HORIZONTAL" or shown_w >= shown_h:
        return 2.0 * math.atan(math.tan(angle_x / 2.0) * shown_h / shown_w)
    return float(angle_x)  # AUTO, portrait: the sensor width spans the image height


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

