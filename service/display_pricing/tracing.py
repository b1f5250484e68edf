"""Tracing for the tile estimator: whole frames, small-tiled auxiliary frames, and the windows of the
display frame that the sampled blocks need."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from sim_core.image import linear_to_srgb, source_span, upsample_bilinear
from sim_core.render import COUNTER_NAMES

import sim_core
from service.display_pricing.sampling import CameraDesign, block_of
from service.display_pricing.windows import Window, apron_pixels, plan_windows

#: Windows covering tiles whole and pixels: (tile mask, width, height, tile size, apron pixels, pixel mask)
#: -> windows (``plan_windows``).
WindowPlan = Callable[[np.ndarray, int, int, int, int, np.ndarray], list[Window]]

#: Tile side of the auxiliary frames: small, so that their tiles fall into single blocks.
AUX_TILE = 4


class Renderer:
    """The scene and thread count one pricing task renders with."""

    def __init__(self, scene: Any, threads: int | None) -> None:
        self.scene, self.threads = scene, threads

    def frame(self, camera: Any, settings: Any) -> Any:
        return sim_core.render(self.scene, camera, settings, threads=self.threads)

    def aux_frame(self, camera: Any, settings: Any) -> Any:
        """An auxiliary frame: small tiles, so that per-tile counters say where the work is."""
        return self.frame(camera, dataclasses.replace(settings, tile_size=AUX_TILE))

    def windows(self, camera: Any, settings: Any, blocks: Sequence[int], d: CameraDesign,
                plan: WindowPlan | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
        """Trace what the sampled ``blocks`` need at display resolution: the traced-resolution canvas
        (the needed pixels filled), and the counters and histograms of the tiles whose centre lies in a
        sampled block (rows in the frame's tile order), with those tiles' blocks. Whatever windows ``plan``
        (default ``plan_windows``) chooses, as long as they cover the needed pixels and hold each sampled
        tile whole, the pixels and each sampled tile's counters are the whole frame's (a window keeps the
        frame's tile grid; the tiles holding only needed pixels are traced where they are needed): the plan
        changes only the cost."""
        s = settings
        w, h = sim_core.render_size(camera, s)
        ts = s.tile_size
        need, owner, counted, tiles = needed_tiles(d, blocks, w, h, ts)
        ntx = tiles.shape[1]  # tile columns: the grid needed_tiles laid out
        whole_w = np.minimum(ts, w - np.arange(ntx) * ts)  # the frame's tile sizes
        whole_h = np.minimum(ts, h - np.arange(tiles.shape[0]) * ts)
        canvas = np.zeros((h, w, 3), dtype=np.float32)
        covered = np.zeros((h, w), dtype=bool)
        rows_c: list[np.ndarray] = []
        rows_h: list[np.ndarray] = []
        rows_b: list[np.ndarray] = []
        rows_t: list[np.ndarray] = []  # the tiles' row-major index: one order whatever the windows
        traced = np.zeros(counted.size, dtype=bool)  # sampled tiles already traced whole
        for win in (plan or plan_windows)(counted, w, h, ts, apron_pixels(s), need):
            x, y, ww, wh = win
            r = sim_core.render_window(self.scene, camera, s, win, threads=self.threads)
            canvas[y:y + wh, x:x + ww] = r.image
            covered[y:y + wh, x:x + ww] = True
            tx = np.asarray([t["x0"] // ts for t in r.tile_stats], dtype=np.int64)
            ty = np.asarray([t["y0"] // ts for t in r.tile_stats], dtype=np.int64)
            index = ty * ntx + tx
            # a sampled tile's counters come from a window holding it whole (the frame's), once
            whole = np.asarray([t["x0"] % ts == 0 and t["y0"] % ts == 0 and t["width"] == whole_w[i]
                                and t["height"] == whole_h[j]
                                for t, i, j in zip(r.tile_stats, tx, ty, strict=True)], dtype=bool)
            keep = counted.ravel()[index] & whole & ~traced[index]
            traced[index[keep]] = True
            if keep.any():
                rows_c.append(r.tile_counters[keep])
                rows_h.append(r.tile_histograms[keep])
                rows_b.append(owner.ravel()[index[keep]])
                rows_t.append(index[keep])
        if not covered[need].all():
            raise RuntimeError("tile estimator: a needed pixel was not traced")
        if not traced[counted.ravel()].all():
            raise RuntimeError("tile estimator: a sampled tile was not traced whole")
        if not rows_t:
            return (canvas, np.zeros((0, len(COUNTER_NAMES)), np.uint64), np.zeros((0, 25), np.uint64),
                    np.zeros(0, np.int64), (w, h))
        order = np.argsort(np.concatenate(rows_t), kind="stable")
        return (canvas, np.concatenate(rows_c)[order], np.concatenate(rows_h)[order],
                np.concatenate(rows_b)[order], (w, h))


def needed_tiles(d: CameraDesign, blocks: Sequence[int], w: int, h: int, ts: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What the sampled ``blocks`` need of a ``w`` x ``h`` traced frame with ``ts``-pixel tiles: the
    pixels their regions read (h, w), each tile's block (by its centre), the tiles whose counters are the
    sample's (their centre in a sampled block: traced whole), and every tile holding one of those or a
    needed pixel (what tracing whole tiles would trace); tile arrays (rows of tiles, columns of tiles)."""
    ntx, nty = -(-w // ts), -(-h // ts)
    need = np.zeros((h, w), dtype=bool)  # traced pixels the regions read
    for b in blocks:
        x0, y0, x1, y1 = d.regions[b]
        sx0, sx1 = source_span(d.W, w, x0, x1)
        sy0, sy1 = source_span(d.H, h, y0, y1)
        need[sy0:sy1, sx0:sx1] = True
    # tiles whose centre lies in a sampled block: their counters are the sample's
    tx, ty = np.meshgrid(np.arange(ntx), np.arange(nty))
    tw = np.minimum(ts, w - tx * ts)
    th = np.minimum(ts, h - ty * ts)
    cx = tx * ts + 0.5 * tw
    cy = ty * ts + 0.5 * th
    owner = block_of(cx.ravel(), cy.ravel(), d.W / w, d.H / h, d.B, d.nbx, d.nby).reshape(nty, ntx)
    counted = np.isin(owner, np.asarray(blocks))
    # every tile holding a sampled tile or a needed pixel
    per_tile = np.add.reduceat(np.add.reduceat(need.astype(np.int32), np.arange(0, h, ts), axis=0),
                               np.arange(0, w, ts), axis=1)
    return need, owner, counted, counted | (per_tile > 0)


def display_patches(canvas: np.ndarray, size: tuple[int, int], d: CameraDesign, blocks: Sequence[int]
                    ) -> dict[int, np.ndarray]:
    """Display-transformed display pixels over every sampled block's region (bit for bit the whole
    frame's upsampling)."""
    out = {}
    for b in blocks:
        out[b] = linear_to_srgb(upsample_bilinear(canvas, d.H, d.W, window=d.regions[b]))
    return out
