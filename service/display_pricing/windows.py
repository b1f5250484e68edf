"""Which windows of the traced frame the tile estimator renders: few, large ones.

A window that goes through the resolve pass (FSAA or supersampling, or AO) also traces an apron of a
few pixels around itself (what the pixel filter and the ambient pool read, ``sim_core.window_apron``), so
that its pixels are the whole frame's (``sim_core.render_window``). Many small windows each pay that apron
and a call each. This module chooses, for the tiles whose counters are used (traced whole) and the pixels the
SSIM reads, windows that cover them with the least traced area it finds (aprons included), and never
more than the whole frame: the whole frame is one of the candidates. A window keeps the frame's tile
grid, so it may cut a tile that holds only pixels the SSIM reads (a block's margin) and trace just them.
Which windows are traced changes only the cost: a window traces the frame's pixels, and the tiles whole
in it with the frame's per-tile counters."""

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


class _Reads:
    """The pixels a plan must cover (a ``height`` x ``width`` mask), with the prefix sums that give the
    pixels' columns in a band of tile rows and their rows in a rectangle."""

    def __init__(self, pixels: np.ndarray, tile: int) -> None:
        self.pixels, self.tile = pixels, tile
        h, w = pixels.shape
        starts = np.arange(0, h, tile)
        per_tile_row = np.add.reduceat(pixels.astype(np.int32), starts, axis=0)  # (tile rows, w)
        self.band_cols = np.concatenate([np.zeros((1, w), np.int32), np.cumsum(per_tile_row, axis=0)])
        self.row_prefix = np.concatenate([np.zeros((h, 1), np.int32),
                                          np.cumsum(pixels, axis=1, dtype=np.int32)], axis=1)

    def band(self, r0: int, r1: int, apron: int) -> list[Window]:
        """Windows over tile rows [r0, r1): one per run of the columns holding a pixel (joined across
        gaps that cost no more than the two aprons they save), each cut to the rows holding one."""
        h = self.pixels.shape[0]
        y0, y1 = r0 * self.tile, min(r1 * self.tile, h)
        runs = _merged_runs(self.band_cols[r1] - self.band_cols[r0] > 0, 2 * apron)
        if not runs:
            return []
        a, b = np.asarray(runs).T
        rows = self.row_prefix[y0:y1, b] - self.row_prefix[y0:y1, a] > 0  # (band rows, runs)
        first = rows.argmax(axis=0)
        last = rows.shape[0] - rows[::-1].argmax(axis=0)
        return [(int(x0), y0 + int(f), int(x1 - x0), int(t - f))
                for x0, x1, f, t in zip(a, b, first, last, strict=True)]

    def shrink(self, window: Window) -> Window | None:
        """``window`` cut to the bounding box of the pixels in it (None when it holds none)."""
        x, y, w, h = window
        inside = self.pixels[y:y + h, x:x + w]
        cols, rows = np.flatnonzero(inside.any(axis=0)), np.flatnonzero(inside.any(axis=1))
        if cols.size == 0:
            return None
        return (x + int(cols[0]), y + int(rows[0]), int(cols[-1] - cols[0] + 1), int(rows[-1] - rows[0] + 1))


def _bands(reads: _Reads, ntiles: int, width: int, height: int, apron: int) -> list[Window]:
    """Horizontal bands of tile rows covering ``reads``, chosen by dynamic programming over the rows for
    the least traced area (``_Reads.band``'s windows each)."""
    best: list[tuple[int, list[Window]]] = [(0, [])]
    for r1 in range(1, ntiles + 1):
        choice = None
        for r0 in range(r1):
            windows = reads.band(r0, r1, apron)
            cost = traced_area(windows, width, height, apron) + best[r0][0]
            if choice is None or cost < choice[0]:
                choice = (cost, best[r0][1] + windows)
        best.append(choice)
    return best[ntiles][1]


def plan_windows(mask: np.ndarray, width: int, height: int, tile: int, apron: int,
                 reads: np.ndarray | None = None) -> list[Window]:
    """Windows covering every true tile of ``mask`` (rows of tiles, columns of tiles) of a ``width`` x
    ``height`` frame with ``tile``-pixel tiles whole, each inside one window (their per-tile counters are
    the frame's), and every true pixel of ``reads`` (rows, columns; default none), traced with ``apron``
    pixels each side. The windows are disjoint and off the tile grid only where they cut tiles that hold
    ``reads`` pixels alone (``sim_core.render_window`` traces those parts as the frame has them). The
    cheapest (traced area) of the whole frame, bands of tile rows, bands of tile columns and the tiles'
    exact cover by rectangles, each window cut to the pixels it must cover; the whole frame on ties. Never
    traces more than the whole frame."""
    mask = np.asarray(mask, dtype=bool)
    nty, ntx = -(-height // tile), -(-width // tile)
    if mask.shape != (nty, ntx):
        raise ValueError(f"tile mask of shape {mask.shape}, expected {(nty, ntx)}")
    pixels = np.repeat(np.repeat(mask, tile, axis=0), tile, axis=1)[:height, :width]
    if reads is not None:
        reads = np.asarray(reads, dtype=bool)
        if reads.shape != (height, width):
            raise ValueError(f"pixel mask of shape {reads.shape}, expected {(height, width)}")
        pixels = pixels | reads
    if not pixels.any():
        return []
    tiles = np.add.reduceat(np.add.reduceat(pixels.astype(np.int32), np.arange(0, height, tile), axis=0),
                            np.arange(0, width, tile), axis=1) > 0
    by_rows, by_cols = _Reads(pixels, tile), _Reads(np.ascontiguousarray(pixels.T), tile)
    rows = _bands(by_rows, nty, width, height, apron)
    cols = [(y, x, h, w) for x, y, w, h in _bands(by_cols, ntx, height, width, apron)]
    exact = [w for w in map(by_rows.shrink, _to_pixels(cover_rects(tiles), width, height, tile)) if w]
    candidates = [[(0, 0, width, height)], rows, cols, exact]
    return min(candidates, key=lambda ws: traced_area(ws, width, height, apron))
