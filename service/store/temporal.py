"""The temporal filter of playback: settings move from the old to a new target over a period T, along
the frontier.

The power-budget paper's Eq. 8 blends each parameter's value index separately,
``s = round((1 - t/T) * s_old + (t/T) * s_new)``; a blended setting then lies on no frontier, so its
power and error are not predicted and, where neighbouring octree samples pick targets of different kinds,
it can break the budget (the hall kept its power budget on 83 % of frames that way). This filter keeps
Eq. 8's pace and shows, on every frame, the frontier point nearest to Eq. 8's blend among the points the
caller allows: the points of the current frame's frontier that keep the budget
(:meth:`service.store.ParetoStore.budget_points`). So every shown setting is a stored, predicted point
that keeps the budget whenever the target does, and the filter still never jumps at once from the old
settings to the new ones: at the moment the target changes it keeps showing the settings on screen when
they are allowed, and it reaches the target after exactly T.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Indices = tuple[int, ...]


def _distance(a: Sequence[float], b: Sequence[float]) -> float:
    return sum(abs(x - y) for x, y in zip(a, b, strict=True))


def blend(old: Sequence[int], target: Sequence[int], progress: float,
          allowed: Sequence[Sequence[int]] | None = None, bound: float = math.inf) -> Indices:
    """The setting shown ``progress`` (t / T) of the way from ``old`` to ``target``.

    Without ``allowed``: Eq. 8 (each index blended and rounded). With ``allowed`` (settings that include
    ``target``): the allowed setting nearest (L1 over value indices) to Eq. 8's unrounded blend, among
    those at most ``bound`` from the target (the filter passes the distance of the setting it showed last,
    so it never moves away from its target); ties go to the one nearer the target, then to the first.
    ``progress >= 1`` gives the target."""
    goal = tuple(int(v) for v in target)
    if progress >= 1.0:
        return goal
    a = max(0.0, float(progress))
    b = 1.0 - a
    point = [b * o + a * n for o, n in zip(old, goal, strict=True)]
    if allowed is None:
        return tuple(math.floor(v + 0.5) for v in point)
    best: Indices | None = None
    best_key = (math.inf, math.inf)
    for candidate in allowed:
        to_goal = _distance(candidate, goal)
        if to_goal > bound:
            continue
        key = (_distance(candidate, point), to_goal)
        if key < best_key:
            best, best_key = tuple(int(v) for v in candidate), key
    return goal if best is None else best


class TemporalFilter:
    """Move the shown settings from the old ones to a new target over ``period_s`` (T).

    ``update(target, now_s, allowed)`` once per frame: ``t`` is the time since the target last changed;
    a change in the middle of a transition starts the next one from the settings shown at that moment.
    With ``allowed`` (the settings that may be shown on this frame, the target among them) the shown
    setting is always one of them (:func:`blend`) and never further from the target than the one shown
    on the previous frame of the same transition; without it, the paper's Eq. 8. After T the target
    holds. Time going backwards (scrubbing the timeline) snaps to the target; ``period_s = 0`` disables
    filtering.
    """

    def __init__(self, period_s: float = 2.0) -> None:
        if not (math.isfinite(period_s) and period_s >= 0):
            raise ValueError("period_s must be finite and >= 0")
        self.period_s = float(period_s)
        self.reset()

    def reset(self) -> None:
        self._old: Indices | None = None
        self._target: Indices | None = None
        self._shown: Indices | None = None
        self._t0 = 0.0
        self._last_t = -math.inf

    @property
    def shown(self) -> Indices | None:
        """The settings the last update returned (None before the first)."""
        return self._shown

    def update(self, target_indices: Sequence[int], now_s: float,
               allowed: Sequence[Sequence[int]] | None = None) -> Indices:
        """Settings to show at time ``now_s`` (seconds) given the current target indices and, optionally,
        the settings allowed on this frame (they must include the target)."""
        now = float(now_s)
        if not math.isfinite(now):
            raise ValueError("now_s must be finite")
        target = tuple(map(int, target_indices))
        if target and min(target) < 0:
            raise ValueError("indices must be non-negative")
        if allowed is not None:
            allowed = [tuple(map(int, a)) for a in allowed]
            if target not in allowed:
                raise ValueError("the allowed settings must include the target")
        if self._target is None or now < self._last_t:
            self._old, self._target, self._t0 = None, target, now
        elif target != self._target:
            if len(target) != len(self._target):
                raise ValueError("target changed its number of parameters")
            self._old, self._target, self._t0 = self._shown, target, now
        self._last_t = now
        if self._old is None or self.period_s == 0:
            shown = target
        else:
            progress = (now - self._t0) / self.period_s
            if allowed is None:
                shown = blend(self._old, target, progress)
            else:
                bound = math.inf if now == self._t0 or self._shown is None else _distance(self._shown, target)
                shown = blend(self._old, target, progress, allowed, bound)
        if shown == target:
            self._old = None  # arrived: the transition is over
        self._shown = shown
        return shown
