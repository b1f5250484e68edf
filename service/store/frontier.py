"""A Pareto frontier of settings: packed settings with their error, power and (since store format 4)
frame time, in two tiers when frame times are known (since store format 5).

Power is what the GPU draws at the frame rate it reaches, so a setting that misses the target frame
rate draws little because it delivers few frames, not because it is cheap: the settings that meet the
rate and those that miss it are not compared on one front. A frontier keeps

- the *meeting tier*: the (power, error) Pareto front of the settings that meet the frame rate, and
- the *slow tier*: the Pareto front of the settings that miss it but are more accurate than the most
  accurate meeting one (the maximum-quality setting, error 0, ends it unless it meets the rate): what a
  budget that no real-time setting keeps can still be kept with;

in that order, each tier power ascending and error descending, so error descends over the whole
frontier. When no setting meets the rate (or frame times are unknown) there is one tier, the front of
every setting.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from .frame_rate import meets_frame_rate

#: A frontier point as the search and the display pricing hold it: (settings, error, power, frame time, ...).
PointT = TypeVar("PointT", bound=tuple[Any, ...])


def _front(candidates: np.ndarray, error: np.ndarray, power: np.ndarray) -> list[int]:
    """The non-dominated ``candidates`` (indices), power ascending (ties in both: the first one)."""
    order = candidates[np.lexsort((error[candidates], power[candidates]))]  # by power, then error
    keep: list[int] = []
    best = math.inf
    for i in order:
        if error[i] < best:
            keep.append(int(i))
            best = error[i]
    return keep


def frontier_tiers(error: Iterable[float], power: Iterable[float], meets: Iterable[bool] | None = None
                   ) -> tuple[list[int], list[int]]:
    """Indices of the meeting tier and of the slow tier of settings with ``error`` and ``power`` and,
    optionally, whether each ``meets`` the frame rate (the one two-tier rule: the search, the display
    pricing and the store use it). Without ``meets``, or when no setting meets the rate: (the front of
    all of them, [])."""
    e = np.asarray(list(error), dtype=np.float64)
    p = np.asarray(list(power), dtype=np.float64)
    every = np.arange(e.size)
    m = None if meets is None else np.asarray(list(meets), dtype=bool)
    if m is None or not m.any():
        return _front(every, e, p), []
    fast = _front(every[m], e, p)
    best = e[fast[-1]]  # the most accurate meeting setting ends the meeting tier
    return fast, _front(every[~m & (e < best)], e, p)


def split_by_rate(points: Sequence[PointT], fps: float | None) -> tuple[list[PointT], list[PointT]]:
    """(meeting, slow): the ``points`` ((settings, error, power, frame time, ...), in their order) that
    keep up with ``fps`` and those that miss it, by :func:`.frame_rate.meets_frame_rate` on each point's
    frame time. One tier, (all of them, []), without ``fps`` or when none keeps up: the same rule as
    :func:`frontier_tiers`, for point lists (the search's warm starts and comparisons, the display
    pricing's choice of points)."""
    if fps is None:
        return list(points), []
    meeting: list[PointT] = []
    slow: list[PointT] = []
    for pt in points:
        (meeting if meets_frame_rate(float(pt[3]), fps) else slow).append(pt)
    return (meeting, slow) if meeting else (list(points), [])


@dataclass(frozen=True)
class Frontier:
    """A frontier: packed settings with error and power and each setting's frame time at the path's
    resolution (``None``: unknown, stores before format 4), as the module docstring orders them: the
    meeting tier then the slow tier (:meth:`tiers`), each power ascending, error descending throughout."""

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
        """The frontier of some settings: the non-dominated points (ties: first occurrence) sorted by
        power, or, with frame times and the target ``fps``, the two tiers (:func:`frontier_tiers`)."""
        pk = np.asarray(list(packed), dtype=np.uint32)
        e = np.asarray(list(error), dtype=np.float64)
        p = np.asarray(list(power_w), dtype=np.float64)
        if not (pk.shape == e.shape == p.shape) or pk.ndim != 1 or pk.size == 0:
            raise ValueError("a frontier needs equally long, non-empty packed/error/power lists")
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(p))):
            raise ValueError("frontier error and power must be finite")
        t = None
        meets = None
        if frame_time_s is not None:
            t = np.asarray(list(frame_time_s), dtype=np.float64)
            if t.shape != pk.shape or not np.all(np.isfinite(t)) or np.any(t < 0):
                raise ValueError("frame times must be finite, >= 0 and one per setting")
            if fps is None or not (math.isfinite(fps) and fps > 0):
                raise ValueError("frame times need the target fps (finite, > 0)")
            meets = [meets_frame_rate(float(v), fps) for v in t]
        fast, slow = frontier_tiers(e, p, meets)
        k = np.asarray(fast + slow, dtype=np.int64)
        return Frontier(pk[k], e[k], p[k], None if t is None else t[k])

    def __len__(self) -> int:
        return int(self.packed.size)

    def _subset(self, keep: np.ndarray) -> Frontier:
        assert self.frame_time_s is not None
        return Frontier(self.packed[keep], self.error[keep], self.power_w[keep], self.frame_time_s[keep])

    def tiers(self, fps: float) -> tuple[Frontier, Frontier | None]:
        """(meeting tier, slow tier) at ``fps``: the points that meet it and those that miss it; (this
        frontier, None) when frame times are unknown, or when no point or every point meets it."""
        if self.frame_time_s is None:
            return self, None
        keep = np.asarray([meets_frame_rate(float(v), fps) for v in self.frame_time_s], dtype=bool)
        if keep.all() or not keep.any():
            return self, None
        return self._subset(keep), self._subset(~keep)

    def meeting(self, fps: float) -> Frontier:
        """The points that meet ``fps`` (this frontier itself when frame times are unknown, or when no
        point or every point meets it): the meeting tier."""
        return self.tiers(fps)[0]

    def under_power(self, budget: float) -> tuple[int, bool]:
        """Index of the least error with power <= budget; (cheapest, True) when none fits. On one tier
        (a frontier without a slow tier, or :meth:`tiers`' parts)."""
        i = int(np.searchsorted(self.power_w, budget, side="right")) - 1
        return (0, True) if i < 0 else (i, False)

    def under_error(self, budget: float) -> tuple[int, bool]:
        """Index of the least power with error <= budget; (most accurate, True) when none fits. On one
        tier (a frontier without a slow tier, or :meth:`tiers`' parts)."""
        # error is descending: search on the negated (ascending) array
        i = int(np.searchsorted(-self.error, -budget, side="left"))
        return (len(self) - 1, True) if i >= len(self) else (i, False)
