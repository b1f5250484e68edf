"""The temporal filter of playback: settings move from the old to a new target over a period T, along
the frontier, at an even pace in predicted error.

The power-budget paper's Eq. 8 blends each parameter's value index separately,
``s = round((1 - t/T) * s_old + (t/T) * s_new)``; a blended setting then lies on no frontier, so its
power and error are not predicted and, where neighbouring octree samples pick targets of different kinds,
it can break the budget (the hall kept its power budget on 83 % of frames that way). The filter therefore
shows, on every frame, one of the settings the caller allows: the points of the current frame's frontier
that keep the budget (:meth:`service.store.ParetoStore.budget_points`), each with its predicted error. So
every shown setting is a stored, predicted point that keeps the budget whenever the target does.

Which allowed point: the one whose predicted error is nearest to Eq. 8's pace applied to the error,
``(1 - t/P) * e_start + (t/P) * e_target``, ``e_start`` the predicted error of the setting on screen when
the target changed. The transition's period ``P`` is T for a move across the whole error span of the
frame's allowed points and proportionally shorter for a shorter move (:func:`transition_period`): the
shown error never moves faster than that span per T, and a new target near the on-screen quality (targets
change every second or so as the camera crosses view cubes) is reached soon instead of after a full T.

Blending value indices instead and taking the allowed point nearest in index space (the previous rule)
picked cheap points far from both ends whenever the frontier's points are spread unevenly in index space,
and every target change restarted a full T, so in the power-budget mode the shown settings sat far below
the budget while the camera moved (the hall: mean predicted error 0.255 against 0.175 unfiltered). In
error the shown quality changes evenly, which is what the filter is for (no visible jump), and it never
detours through points less accurate than both ends. Index distance to Eq. 8's blend only breaks ties.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

Indices = tuple[int, ...]


def _distance(a: Sequence[float], b: Sequence[float]) -> float:
    return sum(abs(x - y) for x, y in zip(a, b, strict=True))


def _eq8(old: Sequence[int], target: Sequence[int], a: float) -> list[float]:
    return [(1.0 - a) * o + a * n for o, n in zip(old, target, strict=True)]


def blend(old: Sequence[int], target: Sequence[int], progress: float,
          allowed: Mapping[Sequence[int], float] | None = None, start_error: float | None = None,
          bound: float = math.inf) -> Indices:
    """The setting shown ``progress`` (time since the change / the transition's period) of the way from
    ``old`` to ``target``.

    Without ``allowed``: Eq. 8 (each index blended and rounded). With ``allowed`` (each setting that may
    be shown, the target among them, mapped to its predicted error): the allowed setting whose error is
    nearest to ``(1 - progress) * start_error + progress * error(target)``, among those whose error is at
    most ``bound`` from the target's (the filter passes the distance of the setting it showed last, so it
    never moves away from its target); ties go to the one nearer (in value indices) to Eq. 8's blend, then
    to the first. ``start_error`` defaults to ``old``'s error when ``old`` is allowed, else to that of the
    allowed setting nearest to ``old`` in value indices. ``progress >= 1`` gives the target."""
    goal = tuple(int(v) for v in target)
    if progress >= 1.0:
        return goal
    if allowed is None:
        return tuple(math.floor(v + 0.5) for v in _eq8(old, goal, max(0.0, float(progress))))
    return _blend_points(old, goal, progress, _allowed_points(allowed, goal), start_error, bound)


def _allowed_points(allowed: Mapping[Sequence[int], float], target: Indices) -> dict[Indices, float]:
    """``allowed`` keyed by integer index tuples, as the blend looks settings up (converted once per
    frame: the filter hands the result on to :func:`_blend_points`)."""
    points = {tuple(int(v) for v in k): float(e) for k, e in allowed.items()}
    if target not in points:
        raise ValueError("the allowed settings must include the target")
    return points


def _blend_points(old: Sequence[int], goal: Indices, progress: float, points: Mapping[Indices, float],
                  start_error: float | None, bound: float) -> Indices:
    """:func:`blend` over allowed settings already keyed as :func:`_allowed_points` keys them."""
    if progress >= 1.0:
        return goal
    a = max(0.0, float(progress))
    point = _eq8(old, goal, a)
    if start_error is None:
        start_error = points[_start_point(old, goal, points)]
    e_goal = points[goal]
    wanted = (1.0 - a) * float(start_error) + a * e_goal
    best, best_key = goal, (math.inf, math.inf)
    for candidate, error in points.items():
        if abs(error - e_goal) > bound:
            continue
        key = (abs(error - wanted), _distance(candidate, point))
        if key < best_key:
            best, best_key = candidate, key
    return best


def transition_period(period_s: float, start_error: float, target_error: float,
                      allowed_errors: Iterable[float]) -> float:
    """How long a transition from ``start_error`` to ``target_error`` lasts: ``period_s`` (T) times its
    share of the error span of the allowed points (at least the move itself), so a move across the whole
    span takes T and a move of a tenth of it a tenth of T; 0 when the errors are equal."""
    move = abs(float(start_error) - float(target_error))
    errors = list(allowed_errors)
    span = max(move, max(errors) - min(errors)) if errors else move
    return float(period_s) * (move / span) if span > 0 else 0.0


def _start_point(old: Sequence[int], target: Sequence[int], allowed: Mapping[Indices, float]) -> Indices:
    """``old`` when it is allowed, else the allowed setting nearest to it in value indices (ties: nearer
    the target): where a transition starts when the error ``old`` was shown at is not known."""
    o = tuple(int(v) for v in old)
    if o in allowed:
        return o
    return min(allowed, key=lambda c: (_distance(c, o), _distance(c, target)))


class TemporalFilter:
    """Move the shown settings from the old ones to a new target within ``period_s`` (T).

    ``update(target, now_s, allowed)`` once per frame: ``t`` is the time since the target last changed;
    a change in the middle of a transition starts the next one from the settings shown at that moment.
    With ``allowed`` (the settings that may be shown on this frame, the target among them, each mapped to
    its predicted error on this frame) the shown setting is always one of them (:func:`blend`: an even
    pace in predicted error from the setting on screen to the target, over :func:`transition_period`, at
    most T) and its error is never further from the target's than the one shown on the previous frame of
    the same transition; at the change itself the settings on screen stay while they are allowed. Without
    it, the paper's Eq. 8 over T. The target holds at the latest T after it last changed. Time going
    backwards (scrubbing the timeline) snaps to the target; ``period_s = 0`` disables filtering.
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
        self._shown_error: float | None = None  # the shown setting's predicted error (None: not given)
        self._start_error: float | None = None
        self._gap = math.inf  # |error(shown) - error(target)| on the last frame of this transition
        self._period = self.period_s  # this transition's period (transition_period)
        self._t0 = 0.0
        self._last_t = -math.inf

    @property
    def shown(self) -> Indices | None:
        """The settings the last update returned (None before the first)."""
        return self._shown

    def update(self, target_indices: Sequence[int], now_s: float,
               allowed: Mapping[Sequence[int], float] | None = None) -> Indices:
        """Settings to show at time ``now_s`` (seconds) given the current target indices and, optionally,
        the settings allowed on this frame mapped to their predicted errors (the target among them)."""
        now = float(now_s)
        if not math.isfinite(now):
            raise ValueError("now_s must be finite")
        target = tuple(map(int, target_indices))
        if target and min(target) < 0:
            raise ValueError("indices must be non-negative")
        points: dict[Indices, float] | None = None
        if allowed is not None:
            points = _allowed_points(allowed, target)
            if not all(math.isfinite(e) for e in points.values()):
                raise ValueError("predicted errors must be finite")
        if self._target is None or now < self._last_t:
            self._old, self._target, self._t0 = None, target, now
        elif target != self._target:
            if len(target) != len(self._target):
                raise ValueError("target changed its number of parameters")
            self._old, self._target, self._t0 = self._shown, target, now
            self._start_error, self._gap, self._period = None, math.inf, self.period_s
            if points is not None and self._old is not None:
                # the error the setting on screen has here, else the one it was shown at
                if self._old in points or self._shown_error is None:
                    self._start_error = points[_start_point(self._old, target, points)]
                else:
                    self._start_error = self._shown_error
                self._period = transition_period(self.period_s, self._start_error, points[target],
                                                 points.values())
        self._last_t = now
        if self._old is None or self.period_s == 0:
            shown = target
        else:
            if points is None:
                shown = blend(self._old, target, (now - self._t0) / self.period_s)
            else:
                elapsed = now - self._t0
                progress = elapsed / self._period if self._period > 0 else (1.0 if elapsed > 0 else 0.0)
                shown = _blend_points(self._old, target, progress, points, self._start_error, self._gap)
        if shown == target:
            self._old = None  # arrived: the transition is over
        self._shown = shown
        if points is None:
            self._shown_error, self._gap = None, math.inf
        else:
            self._shown_error = points[shown]
            self._gap = abs(points[shown] - points[target])
        return shown
