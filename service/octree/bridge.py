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
(:func:`bridge_candidates`; the store keeps the non-dominated points of all it priced). Pure logic.
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


def bridge_candidates(points: Sequence[tuple[Any, ...]], fps: float | None, k: int,
                      priced: Collection[tuple[int, ...]]) -> list[tuple[int, ...]]:
    """At most ``k`` settings (index tuples) not in ``priced`` to price between the gaps of ``points``
    ((indices, error, power, frame time) priced at display resolution): for each gap, widest first and
    in turns (one setting of each gap, then the next of each), the cheaper end with one parameter of the
    dearer end, parameters in the space's order."""
    if k <= 0:
        return []
    per_gap = []
    for _, cheap, dear in gaps(points, fps):
        lo, hi = tuple(int(v) for v in cheap[0]), tuple(int(v) for v in dear[0])
        per_gap.append([(*lo[:p], hi[p], *lo[p + 1:]) for p in range(len(lo)) if lo[p] != hi[p]])
    out: list[tuple[int, ...]] = []
    seen = {tuple(int(v) for v in x) for x in priced}
    for turn in range(max((len(c) for c in per_gap), default=0)):
        for cands in per_gap:
            if turn < len(cands) and cands[turn] not in seen:
                seen.add(cands[turn])
                out.append(cands[turn])
                if len(out) == k:
                    return out
    return out
