"""Eq. 8 of the power-budget paper: settings move from the old to a new target over a period."""

from __future__ import annotations

import math
from collections.abc import Sequence


class TemporalFilter:
    """Blend parameter indices from the old settings to a new target.

    ``s = round((1 - t/T) * s_old + (t/T) * s_new)`` per parameter, with ``t`` the time since the target
    changed; after ``T`` (``period_s``) the target holds. A target change in the middle of a transition
    starts the next transition from the settings shown at that moment. Time going backwards (scrubbing
    the timeline) snaps to the target; ``period_s = 0`` disables filtering.
    """

    def __init__(self, period_s: float = 2.0) -> None:
        if not (math.isfinite(period_s) and period_s >= 0):
            raise ValueError("period_s must be finite and >= 0")
        self.period_s = float(period_s)
        self.reset()

    def reset(self) -> None:
        self._old: tuple[int, ...] | None = None
        self._target: tuple[int, ...] | None = None
        self._t0 = 0.0
        self._last_t = -math.inf

    def _blend(self, now_s: float) -> tuple[int, ...]:
        assert self._target is not None
        if self._old is None or self.period_s == 0:
            return self._target
        a = (now_s - self._t0) / self.period_s
        if a >= 1.0:
            return self._target
        b = 1.0 - a
        floor = math.floor
        return tuple([floor(b * o + a * n + 0.5) for o, n in zip(self._old, self._target, strict=True)])

    def update(self, target_indices: Sequence[int], now_s: float) -> tuple[int, ...]:
        """Settings to use at time ``now_s`` (seconds) given the current target indices."""
        now = float(now_s)
        if not math.isfinite(now):
            raise ValueError("now_s must be finite")
        target = tuple(map(int, target_indices))
        if target and min(target) < 0:
            raise ValueError("indices must be non-negative")
        if self._target is None or now < self._last_t:
            self._old, self._target, self._t0 = None, target, now
        elif target != self._target:
            if len(target) != len(self._target):
                raise ValueError("target changed its number of parameters")
            shown = self._blend(now)
            self._old, self._target, self._t0 = shown, target, now
        self._last_t = now
        return self._blend(now)
