"""Which windows of the traced frame the tile estimator renders: few, large ones.

A window that goes through the resolve pass (FSAA or supersampling, or AO) also traces an apron of a
few pixels around itself (what the pixel filter and the ambient pool read, ``sim_core.window_apron``), so
that its pixels are the whole frame's (``sim_core.render_window``). Many small windows each pay that apron
and a call each. This module chooses, for a mask of tiles that must be traced, windows on the tile grid
that cover it with the least traced area it finds (aprons included), and never more than the whole
frame: the whole frame is one of the candidates.
Which windows are traced changes only the cost: a window on the tile grid traces exactly the frame's
tiles there (pixels and per-tile counters)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

import sim_core
from service.display_pricing.sampling import cover_rects

#: A window as (x, y, width, height) in pixels of the traced frame.
Window = tuple[int, int, int, int]


def apron_pixels(settings: Any) -> int:
    """Pixels the native core traces beyond each edge of a window for ``settings``
    (``sim_core.window_apron``: 0 without a resolve pass, 1-3 for the filters' reach, a few more for the
    reference cells of the adaptive modes). Counts AO whenever ``ao_samples`` > 0 (the core adds it only
    under a world that gives light): an overestimate of the cost, never an underestimate."""
    return sim_core.window_apron(settings, ambient=True)


def traced_area(windows: Sequence[Window], width: int, height: int, apron: int) -> int:
    """Pixels traced by rendering each of ``windows`` alone (their aprons of ``apron`` pixels each side
    included, clipped to the ``width`` x ``height`` frame); a window that is the whole frame has no
    apron."""
    total = 0
    for x, y, w, h in windows:
        a = 0 if (w, h) == (width, height) else apron
        x0, y0 = max(0, x - a), max(0, y - a)
        x1, y1 = min(width, x + w + a), min(height, y + h + a)
        total += (x1 - x0) * (y1 - y0)
    return total


def _to_pixels(rects: Sequence[tuple[int, int, int, int]], width: int, height: int, tile: int
               ) -> list[Window]:
    """Tile rectangles (tx0, ty0, tx1, ty1) as pixel windows clipped to the frame."""
    out = []
    for tx0, ty0, tx1, ty1 in rects:
        x, y = tx0 * tile, ty0 * tile
        out.append((x, y, min(tx1 * tile, width) - x, min(ty1 * tile, height) - y))
    return out


def _merged_runs(columns: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """Runs of true entries, joined across gaps of at most ``gap`` entries."""
    idx = np.flatnonzero(columns)
    if idx.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > gap + 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]]) + 1
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]


def _bands(mask: np.ndarray, width: int, height: int, tile: int, apron: int
           ) -> list[tuple[int, int, int, int]]:
    """Tile rectangles covering ``mask`` as horizontal bands of rows, each band one window per (merged) run
    of the columns it needs; the bands chosen by dynamic programming over the rows for the least traced
    area."""
    nty = mask.shape[0]

    def band(r0: int, r1: int) -> tuple[int, list[tuple[int, int, int, int]]]:
        # filling a gap of g tiles traces no more than the two aprons it replaces when g * tile <= 2 * apron
        runs = _merged_runs(mask[r0:r1].any(axis=0), 2 * apron // tile)
        rects = [(c0, r0, c1, r1) for c0, c1 in runs]
        return traced_area(_to_pixels(rects, width, height, tile), width, height, apron), rects

    best: list[tuple[int, list[tuple[int, int, int, int]]]] = [(0, [])]
    for r1 in range(1, nty + 1):
        choice = None
        for r0 in range(r1):
            cost, rects = band(r0, r1)
            cost += best[r0][0]
            if choice is None or cost < choice[0]:
                choice = (cost, best[r0][1] + rects)
        best.append(choice)
    return best[nty][1]


def plan_windows(mask: np.ndarray, width: int, height: int, tile: int, apron: int) -> list[Window]:
    """Windows on the tile grid covering every true tile of ``mask`` (rows of tiles, columns of tiles) of
    a ``width`` x ``height`` frame with ``tile``-pixel tiles, traced with ``apron`` pixels each side: the
    cheapest (traced area) of the whole frame, bands of rows, bands of columns and the mask's exact cover
    by rectangles; the whole frame on ties. Never traces more than the whole frame."""
    mask = np.asarray(mask, dtype=bool)
    nty, ntx = -(-height // tile), -(-width // tile)
    if mask.shape != (nty, ntx):
        raise ValueError(f"tile mask of shape {mask.shape}, expected {(nty, ntx)}")
    if not mask.any():
        return []
    whole = [(0, 0, width, height)]
    rows = _bands(mask, width, height, tile, apron)
    cols = [(c0, r0, c1, r1) for r0, c0, r1, c1 in _bands(mask.T, height, width, tile, apron)]
    candidates = [whole] + [_to_pixels(r, width, height, tile) for r in (rows, cols, cover_rects(mask))]
    return min(candidates, key=lambda ws: traced_area(ws, width, height, apron))
