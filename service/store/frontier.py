"""A Pareto frontier of settings: packed settings with their error, power and (since store format 4)
frame time."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from .frame_rate import meets_frame_rate


@dataclass(frozen=True)
class Frontier:
    """A Pareto frontier: packed settings with error and power, power ascending, error descending, and
    each setting's frame time at the path's resolution (``None``: unknown, stores before format 4)."""

    packed: np.ndarray  # uint32 (N,)
    error: np.ndarray  # float64 (N,)
    power_w: np.ndarray  # float64 (N,)
    frame_time_s: np.ndarray | None = None  # float64 (N,)

    def __post_init__(self) -> None:
        if self.frame_time_s is not None:
            t = np.asarray(self.frame_time_s, dtype=np.float64)
            if t.shape != np.shape(self.packed) or not np.all(np.isfinite(t)) or np.any(t < 0):
                raise ValueError("frontier frame times must be finite, >= 0 and one per setting")
            object.__setattr__(self, "frame_time_s", t)

    @staticmethod
    def from_points(packed: Iterable[int], error: Iterable[float], power_w: Iterable[float],
                    frame_time_s: Iterable[float] | None = None, fps: float | None = None) -> Frontier:
        """Keep the non-dominated points (ties: first occurrence) and sort them by power.

        With frame times and the target ``fps``: settings that meet the frame rate dominate those that
        miss it, so when any point meets it the frontier is that of the meeting points only (a missing
        setting draws little power because it delivers few frames, not because it is cheap)."""
        pk = np.asarray(list(packed), dtype=np.uint32)
        e = np.asarray(list(error), dtype=np.float64)
        p = np.asarray(list(power_w), dtype=np.float64)
        if not (pk.shape == e.shape == p.shape) or pk.ndim != 1 or pk.size == 0:
            raise ValueError("a frontier needs equally long, non-empty packed/error/power lists")
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(p))):
            raise ValueError("frontier error and power must be finite")
        t = None
        candidates = np.arange(pk.size)
        if frame_time_s is not None:
            t = np.asarray(list(frame_time_s), dtype=np.float64)
            if t.shape != pk.shape or not np.all(np.isfinite(t)) or np.any(t < 0):
                raise ValueError("frame times must be finite, >= 0 and one per setting")
            if fps is None or not (math.isfinite(fps) and fps > 0):
                raise ValueError("frame times need the target fps (finite, > 0)")
            meets = np.asarray([meets_frame_rate(float(v), fps) for v in t], dtype=bool)
            if meets.any():
                candidates = np.flatnonzero(meets)
        sub_e, sub_p = e[candidates], p[candidates]
        order = candidates[np.lexsort((sub_e, sub_p))]  # by power, then error
        keep: list[int] = []
        best_e = math.inf
        for i in order:
            if e[i] < best_e:
                keep.append(int(i))
                best_e = e[i]
        k = np.asarray(keep, dtype=np.int64)
        return Frontier(pk[k], e[k], p[k], None if t is None else t[k])

    def __len__(self) -> int:
        return int(self.packed.size)

    def meeting(self, fps: float) -> Frontier:
        """The points that meet ``fps`` (this frontier itself when frame times are unknown, or when no
        point or every point meets it)."""
        if self.frame_time_s is None:
            return self
        keep = np.asarray([meets_frame_rate(float(v), fps) for v in self.frame_time_s], dtype=bool)
        if keep.all() or not keep.any():
            return self
        return Frontier(self.packed[keep], self.error[keep], self.power_w[keep], self.frame_time_s[keep])

    def under_power(self, budget: float) -> tuple[int, bool]:
        """Index of the least error with power <= budget; (cheapest, True) when none fits."""
        i = int(np.searchsorted(self.power_w, budget, side="right")) - 1
        return (0, True) if i < 0 else (i, False)

    def under_error(self, budget: float) -> tuple[int, bool]:
        """Index of the least power with error <= budget; (most accurate, True) when none fits."""
        # error is descending: search on the negated (ascending) array
        i = int(np.searchsorted(-self.error, -budget, side="left"))
        return (len(self) - 1, True) if i >= len(self) else (i, False)
