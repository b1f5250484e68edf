"""Settings to price at display resolution between a frontier's priced points where their errors jump.

The search chooses a frontier's points from its small images; the display pricing then measures them at
the path's resolution, where a setting's error may be several times what the search saw. On the
`desktop` profile's chess board, for example, dropping one bounce looks harmless at 64x36 (error 0.007)
and costs 0.022-0.038 at 320x180, so at some cameras the priced meeting tier went from Max straight to
errors of 0.04-0.08 while the setting that saves a third of the power at error 0.003 (Max's bounces with
one shadow sample and no ambient occlusion) was a step away, never found by the search there: an error
budget of 0.02 then fell back to Max (bench/RESULTS.md, "Chess's error gap on `desktop`").

Where two neighbouring points of the priced meeting tier (power ascending) differ in error by more than
:data:`GAP_RATIO` (each error plus :data:`ERROR_FLOOR`, so that gaps near Max count as much as gaps far
from it), the settings between them are the cheaper point with one parameter taken from the dearer one:
they keep the cheaper point's savings except where the dearer point differs, one parameter at a time.
The builder prices them at the frontier's cameras and asks again with what it measured, a few rounds
(:func:`bridge_candidates`; the store keeps the non-dominated points of all it priced).

The meeting tier is not the only place the jump shows. Where the GPU cannot run Max at the frame rate
(the lab and the hall on `desktop` at 320x180: Max at 21-29 fps at their heavy cameras), the priced
points were a slow Max and then real-time points from error 0.022-0.14 up, while Max with 4 shadow
samples instead of 16, one step down, keeps 30 fps at error <= 0.0074 at every such frame
(bench/RESULTS.md, "Real-time settings within 0.02 at the lab's and the hall's slow frames"). Bridging
between two real-time points never reaches it. So a frontier whose slow tier holds a point far more
accurate than its meeting tier's most accurate one (:func:`descents`: the same ratio test) also gets that
slow point stepped one value down toward the meeting point, one parameter at a time: each step saves
frame time where the two differ, and a step that still misses the rate is the next round's start.

Neither reaches a trade between two parameters. On the valley at 640x360 (`desktop`), the meeting tier's
most accurate point at one camera had 4 shadow rays and no AO (error 0.022); the slow tier held an adaptive
2x2 point with 1 shadow ray and AO 16 at 0.016 and 27.5 fps, and FSAA with 1 shadow ray and AO 4 keeps 30
fps at 0.018 there (bench/RESULTS.md, "The valley at 640x360 with 16 bridge points"). Stepping toward the
meeting top only lowers AO and raises the shadow rays again. So a slow point that nearly keeps up (frame
time within :data:`NEAR_DEADLINES` deadlines) and is more accurate than the meeting top by any margin is
also stepped one value down in each parameter, toward cheaper settings (:func:`nudges`), with the
points the gaps and descents leave. Pure logic.
"""

from __future__ import annotations

import itertools
from collections.abc import Collection, Sequence
from typing import Any

from service.store import split_by_rate

#: Neighbouring priced errors (with :data:`ERROR_FLOOR` added) further apart than this factor are a gap.
GAP_RATIO = 2.0
#: Added to both errors of a gap's ends: errors below it (a few thousandths of 1 - SSIM) count as equal.
ERROR_FLOOR = 0.001
#: A slow point whose frame time is at most this many frame deadlines nearly keeps up: one value down in
#: one parameter may keep the rate (:func:`nudges`).
NEAR_DEADLINES = 1.25
#: Pricing rounds after the first: a bridge found in one round may open the next one's gap (a parameter
#: the cheap end needs twice), at most this many times.
ROUNDS = 3


def _meeting_front(points: Sequence[tuple[Any, ...]], fps: float | None) -> list[tuple[Any, ...]]:
    """The non-dominated points of the tier that meets ``fps`` (all points without it), power ascending."""
    meeting, _ = split_by_rate(points, fps)
    front: list[tuple[Any, ...]] = []
    for pt in sorted(meeting, key=lambda p: (float(p[2]), float(p[1]))):
        if not front or float(pt[1]) < float(front[-1][1]):
            front.append(pt)
    return front


def gaps(points: Sequence[tuple[Any, ...]], fps: float | None) -> list[tuple[float, tuple[Any, ...],
                                                                            tuple[Any, ...]]]:
    """(ratio, cheaper point, dearer point) of every gap of the priced meeting tier, widest first."""
    front = _meeting_front(points, fps)
    found = []
    for cheap, dear in itertools.pairwise(front):
        ratio = (float(cheap[1]) + ERROR_FLOOR) / (float(dear[1]) + ERROR_FLOOR)
        if ratio > GAP_RATIO:
            found.append((ratio, cheap, dear))
    found.sort(key=lambda g: -g[0])
    return found


def _slow_tier_and_top(points: Sequence[tuple[Any, ...]], fps: float | None
                       ) -> tuple[list[tuple[Any, ...]], tuple[Any, ...] | None]:
    """The priced slow tier and the meeting tier's most accurate point (least error, then least power),
    the point descents and nudges compare the slow tier with; ``([], None)`` without a slow tier."""
    meeting, slow = split_by_rate(points, fps)
    if not slow:
        return [], None
    return slow, min(meeting, key=lambda p: (float(p[1]), float(p[2])))


def descents(points: Sequence[tuple[Any, ...]], fps: float | None) -> list[tuple[float, tuple[Any, ...],
                                                                                tuple[Any, ...]]]:
    """(ratio, slow start, meeting top) where the priced slow tier holds points more accurate than the
    meeting tier's most accurate point (``top``) by more than :data:`GAP_RATIO` (errors with
    :data:`ERROR_FLOOR`): ``start`` is the fastest of them (least frame time, then least power), the one
    nearest to keeping up. Empty without a slow tier (no ``fps``, or no point keeps up)."""
    slow, top = _slow_tier_and_top(points, fps)
    if top is None:
        return []
    bound = float(top[1]) + ERROR_FLOOR
    far = [p for p in slow if bound / (float(p[1]) + ERROR_FLOOR) > GAP_RATIO]
    if not far:
        return []
    start = min(far, key=lambda p: (float(p[3]), float(p[2])))
    return [(bound / (float(start[1]) + ERROR_FLOOR), start, top)]


def nudges(points: Sequence[tuple[Any, ...]], fps: float | None) -> list[tuple[float, tuple[Any, ...],
                                                                              tuple[Any, ...]]]:
    """(ratio, slow start, meeting top) where the priced slow tier holds points more accurate than the
    meeting tier's most accurate point (``top``) that miss the rate by at most :data:`NEAR_DEADLINES`
    frame deadlines: ``start`` is the fastest of them (least frame time, then least error); ``ratio`` is
    top's error over start's (with :data:`ERROR_FLOOR`). Empty without a slow tier."""
    slow, top = _slow_tier_and_top(points, fps)
    if top is None or fps is None:
        return []
    near = [p for p in slow if float(p[1]) < float(top[1]) and float(p[3]) <= NEAR_DEADLINES / fps]
    if not near:
        return []
    start = min(near, key=lambda p: (float(p[3]), float(p[1])))
    return [((float(top[1]) + ERROR_FLOOR) / (float(start[1]) + ERROR_FLOOR), start, top)]


def _steps_down(start: tuple[int, ...]) -> list[tuple[int, ...]]:
    """``start`` with one parameter one value cheaper (values are ordered cheapest first), for each
    parameter above its cheapest value."""
    return [(*start[:p], start[p] - 1, *start[p + 1:]) for p in range(len(start)) if start[p] > 0]


def _step_toward(start: tuple[int, ...], target: tuple[int, ...]) -> list[tuple[int, ...]]:
    """``start`` with one parameter moved one value toward ``target``'s, for each parameter they differ in."""
    return [(*start[:p], start[p] + (1 if target[p] > start[p] else -1), *start[p + 1:])
            for p in range(len(start)) if start[p] != target[p]]


def bridge_candidates(points: Sequence[tuple[Any, ...]], fps: float | None, k: int,
                      priced: Collection[tuple[int, ...]]) -> list[tuple[int, ...]]:
    """At most ``k`` settings (index tuples) not in ``priced`` to price between the gaps of ``points``
    ((indices, error, power, frame time) priced at display resolution): for each gap, widest first and
    in turns (one setting of each gap, then the next of each), the cheaper end with one parameter of the
    dearer end, parameters in the space's order; for a descent (:func:`descents`), ranked by its ratio
    among the gaps, the slow start with one parameter one value nearer the meeting top's; then, with
    what the gaps and descents leave of ``k``, for a nudge (:func:`nudges`) the slow start with one
    parameter one value cheaper."""
    if k <= 0:
        return []
    ranked = []
    for ratio, cheap, dear in gaps(points, fps):
        lo, hi = tuple(int(v) for v in cheap[0]), tuple(int(v) for v in dear[0])
        ranked.append((ratio, [(*lo[:p], hi[p], *lo[p + 1:]) for p in range(len(lo)) if lo[p] != hi[p]]))
    for ratio, start, top in descents(points, fps):
        ranked.append((ratio, _step_toward(tuple(int(v) for v in start[0]), tuple(int(v) for v in top[0]))))
    ranked.sort(key=lambda g: -g[0])
    out: list[tuple[int, ...]] = []
    seen = {tuple(int(v) for v in x) for x in priced}
    # nudges after every gap's and descent's setting, with the points they leave: taking turns with them,
    # nudges displaced the bridge that served a valley frame at 640x360 (bench/RESULTS.md, "Bridging nudges")
    nudged = [_steps_down(tuple(int(v) for v in start[0])) for _, start, _ in nudges(points, fps)]
    for per_gap in ([cands for _, cands in ranked], nudged):
        for turn in range(max((len(c) for c in per_gap), default=0)):
            for cands in per_gap:
                if turn < len(cands) and cands[turn] not in seen:
                    seen.add(cands[turn])
                    out.append(cands[turn])
                    if len(out) == k:
                        return out
    return out
