"""A Pareto frontier of settings: packed settings with their error and power."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frontier:
    """A Pareto frontier: packed settings with error and power, power ascending, error descending."""

    packed: np.ndarray  # uint32 (N,)
    error: np.ndarray  # float64 (N,)
    power_w: np.ndarray  # float64 (N,)

    @staticmethod
    def from_points(packed: Iterable[int], error: Iterable[float], power_w: Iterable[float]) -> Frontier:
        """Keep the non-dominated points (ties: first occurrence) and sort them by power."""
        pk = np.asarray(list(packed), dtype=np.uint32)
        e = np.asarray(list(error), dtype=np.float64)
        p = np.asarray(list(power_w), dtype=np.float64)
        if not (pk.shape == e.shape == p.shape) or pk.ndim != 1 or pk.size == 0:
            raise ValueError("a frontier needs equally long, non-empty packed/error/power lists")
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(p))):
            raise ValueError("frontier error and power must be finite")
        order = np.lexsort((e, p))  # by power, then error
        keep: list[int] = []
        best_e = math.inf
        for i in order:
            if e[i] < best_e:
                keep.append(int(i))
                best_e = e[i]
        k = np.asarray(keep, dtype=np.int64)
        return Frontier(pk[k], e[k], p[k])

    def __len__(self) -> int:
        return int(self.packed.size)

    def under_power(self, budget: float) -> tuple[int, bool]:
        """Index of the least error with power <= budget; (cheapest, True) when none fits."""
        i = int(np.searchsorted(self.power_w, budget, side="right")) - 1
        return (0, True) if i < 0 else (i, False)

    def under_error(self, budget: float) -> tuple[int, bool]:
        """Index of the least power with error <= budget; (most accurate, True) when none fits."""
        # error is descending: search on the negated (ascending) array
        i = int(np.searchsorted(-self.error, -budget, side="left"))
        return (len(self) - 1, True) if i >= len(self) else (i, False)
