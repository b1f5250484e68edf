"""Camera-path helpers shared by recording, export and playback (pure: no bpy; the camera maths itself
 is `service.store.camera`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from service import camera_path


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

