"""Store figures at the path's display resolution: whole frames, or the tile estimator.

The search runs on small preview images; what a store records is priced again at the resolution the
path is shown at (DESIGN.md, fidelity rule). ``"full"`` renders every setting and the maximum-quality
reference as whole frames: exact, and as slow as the frames. ``"tiles"`` (the default) traces a sample
of the frame's blocks at display resolution and estimates the frame's error and activity counters
from it; power and frame time then come from the estimated counters through the energy model, as for
a rendered frame (never from a smaller render scaled by its pixel count).

The tile estimator, for one camera and the settings priced there:

1. **Blocks.** The display frame is cut into ``block`` x ``block`` pixel blocks (64: four 16-pixel
   tiles a side). A setting's traced tiles belong to the block holding their centre (in display
   coordinates, so resolution scales below 1 map too); SSIM's local values belong to their pixel.
2. **Auxiliary frames.** Every setting and the reference are also rendered whole at 1/``aux_divisor``
   of the display size a side (1/16 of the pixels): their per-block error (1 - local SSIM) and per-tile
   counters, x_b, are known for every block.
3. **Sample.** Blocks are drawn with probability proportional to a size measure (mostly where the
   auxiliary frames of three fixed probe settings, the space's cheapest and two intermediate ones,
   differ from the reference; some where the reference's rays go; a floor everywhere), systematically
   along a serpentine path through the frame from a start drawn from the run's seed and the camera:
   a sample spread over the frame, the same for every setting of the camera (one reference), and the
   same whatever else is priced with it (cacheable per setting). A block with a size measure above the
   sampling interval is taken with certainty.
4. **Display-resolution values.** The sampled blocks are traced at display resolution as windows of
   the frame (``sim_core.render_window``: the frame's own pixels and per-tile counters; tiles are cold-
   cache units, so counters add exactly). SSIM needs half a window of margin around a block: whole
   neighbouring tiles for the adaptive modes (their interpolation runs within a tile), only the
   margin's pixels for the per-pixel modes (1 spp, FSAA: the reference among them). y_b = the block's
   sum of 1 - local SSIM (an SSIM of the block and its margin, whose inner part is the block) and its
   tiles' counters.
5. **Ratio estimators.** Y = X * sum(y_b / pi_b) / sum(x_b / pi_b) over the sampled blocks, for the
   error sum and for each counter (pi_b the inclusion probabilities, X the auxiliary frame's total):
   the sample corrects the auxiliary frame's level, the auxiliary frame spreads the sample's values
   over the blocks not traced. Where the auxiliary total is 0 the plain Horvitz-Thompson sum is used.
   The pixel and frame-buffer counters are exact. An approximate standard error (with-replacement
   formula on the ratio's residuals) goes with each figure; the measured error against whole frames
   is in ``bench/RESULTS.md`` (``bench/bench_display_pricing.py``).

Only the SSIM metrics can be estimated from tiles; FLIP is priced on whole frames.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
from sim_core.image import linear_to_srgb, source_span, upsample_bilinear
from sim_core.render import COUNTER_NAMES

import sim_core
from service.eval_cache import CacheKey, Evaluation
from service.evaluation import (  # the evaluator's own error and pricing, so both agree
    PIPELINE_VERSION,
    CameraSpec,
    Evaluator,
    SceneHandle,
    _price,
    image_error,
    space_fingerprint,
)
from service.lru import LRUCache
from service.metrics import GAUSS_SIGMA, GAUSS_TRUNCATE, UNIFORM_WIN, ssim, ssim_map
from service.params import Indices, ParameterSpace

#: How store figures are priced at display resolution (``OptimizeConfig.display_estimator``).
ESTIMATORS = ("tiles", "full")
#: Bumped whenever the estimator's design changes (part of every cache key of its figures).
ESTIMATOR_VERSION = "1"
_COL = {name: i for i, name in enumerate(COUNTER_NAMES)}
#: Blocks a frame is cut into when the block size is not given.
BLOCKS = 240


@dataclass(frozen=True)
class DisplayPricing:
    """How figures are priced at display resolution. ``fraction``: share of the frame's blocks traced
    (their expected number; blocks taken with certainty count once); ``block``: block side in display
    pixels (a multiple of 16, the tile size); ``aux_divisor``: the auxiliary frames' size is the display
    size divided by it; ``seed``: the run's seed (with the camera, it places the sample). ``block``
    None: about :data:`BLOCKS` blocks a frame (64 pixels at 1280x720, 32 at 640x360)."""

    estimator: str = "tiles"
    fraction: float = 0.25
    block: int | None = None
    aux_divisor: int = 4
    seed: int = 0

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"display estimator must be one of {ESTIMATORS}, got {self.estimator!r}")
        if not (isinstance(self.fraction, int | float) and 0.0 < self.fraction <= 1.0):
            raise ValueError(f"display fraction must be in (0, 1], got {self.fraction!r}")
        if self.block is not None and (self.block < 16 or self.block % 16):
            raise ValueError(f"block must be a multiple of 16 pixels, got {self.block}")
        if self.aux_divisor not in (1, 2, 4):
            raise ValueError(f"aux_divisor must be 1, 2 or 4, got {self.aux_divisor}")

    def block_for(self, width: int, height: int) -> int:
        """Block side for a display size: the given one, or about :data:`BLOCKS` blocks a frame."""
        if self.block is not None:
            return self.block
        return max(16, 16 * round(math.sqrt(width * height / BLOCKS) / 16))

    def key(self, metric: str) -> str:
        """What the figures depend on, for cache keys and the store's meta."""
        if self.estimator == "full" or metric == "flip":
            return f"full-v{ESTIMATOR_VERSION}"
        return (f"tiles-v{ESTIMATOR_VERSION}:f={self.fraction:g}:b={self.block or 'auto'}:"
                f"a={self.aux_divisor}:s={self.seed}")

    def label(self, metric: str) -> str:
        """One line for reports."""
        if self.key(metric).startswith("full"):
            return "whole frames"
        return (f"tile estimator ({100 * self.fraction:g} % of the frame's blocks traced at display "
                f"resolution, ratio estimators over 1/{self.aux_divisor}-size whole frames)")


def _pad(metric: str) -> int:
    """Half the SSIM window: the margin a block needs around it, and the border SSIM leaves out."""
    return int(GAUSS_TRUNCATE * GAUSS_SIGMA + 0.5) if metric == "ssim_gaussian" else UNIFORM_WIN // 2


# -- geometry ---------------------------------------------------------------------------------------------
def _rects(mask: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Rectangles (x0, y0, x1, y1) covering the true cells of a 2-D mask exactly: runs along each row,
    consecutive rows with the same runs merged."""
    out: list[tuple[int, int, int, int]] = []
    open_runs: dict[tuple[int, int], int] = {}
    prev: tuple[tuple[int, int], ...] = ()
    for y in range(mask.shape[0] + 1):
        runs: tuple[tuple[int, int], ...] = ()
        if y < mask.shape[0]:
            row = np.concatenate([[False], mask[y], [False]])
            edges = np.flatnonzero(row[1:] != row[:-1])
            runs = tuple((int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True))
        if runs != prev:
            for r in prev:
                out.append((r[0], open_runs.pop(r), r[1], y))
            for r in runs:
                open_runs[r] = y
            prev = runs
    return out


def _block_of(cx: np.ndarray, cy: np.ndarray, scale_x: float, scale_y: float, block: int, nbx: int,
              nby: int) -> np.ndarray:
    """Block index (row-major) of points (traced-frame pixels) mapped to display coordinates."""
    bx = np.clip(np.floor(cx * scale_x / block).astype(np.int64), 0, nbx - 1)
    by = np.clip(np.floor(cy * scale_y / block).astype(np.int64), 0, nby - 1)
    return by * nbx + bx


def _tile_blocks(result: Any, display: tuple[int, int], block: int, nbx: int, nby: int) -> np.ndarray:
    """Block of every tile of a render (by the tile's centre)."""
    w, h = result.render_resolution
    t = result.tile_stats
    cx = np.asarray([s["x0"] + 0.5 * s["width"] for s in t], dtype=np.float64)
    cy = np.asarray([s["y0"] + 0.5 * s["height"] for s in t], dtype=np.float64)
    return _block_of(cx, cy, display[0] / w, display[1] / h, block, nbx, nby)


def serpentine(nbx: int, nby: int) -> np.ndarray:
    """Block indices along rows, every other row reversed (neighbours in the order are neighbours in
    the frame, so a systematic sample along it is spread over the frame)."""
    rows = [np.arange(j * nbx, (j + 1) * nbx) for j in range(nby)]
    return np.concatenate([r if j % 2 == 0 else r[::-1] for j, r in enumerate(rows)])


def inclusion_probabilities(size: np.ndarray, n: float) -> np.ndarray:
    """pi_b proportional to ``size`` with sum n, capped at 1 (blocks over the cap taken with certainty
    and the rest spread over the others)."""
    m = np.asarray(size, dtype=np.float64)
    if m.ndim != 1 or not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise ValueError("size measures must be positive and finite")
    n = min(float(n), float(len(m)))
    pi = np.zeros_like(m)
    sure = np.zeros(len(m), dtype=bool)
    while True:
        rest = ~sure
        pi[sure] = 1.0
        pi[rest] = (n - sure.sum()) * m[rest] / m[rest].sum()
        over = rest & (pi >= 1.0 - 1e-12)
        if not over.any():
            return np.minimum(pi, 1.0)
        sure |= over


def systematic_sample(pi: np.ndarray, order: np.ndarray, start: float) -> np.ndarray:
    """Systematic PPS sample: along ``order``, the units where the running sum of pi crosses start,
    start + 1, ... (``start`` in [0, 1)); each unit is drawn with probability pi exactly."""
    c = np.concatenate([[0.0], np.cumsum(pi[order])])
    points = start + np.arange(math.ceil(c[-1] - start + 1e-9))
    hit = np.searchsorted(c, points, side="right") - 1
    hit = hit[(hit >= 0) & (hit < len(order))]
    return np.unique(order[hit])


def sample_start(seed: int, camera: CameraSpec, pricing_key: str) -> float:
    """The sample's start in [0, 1): from the run's seed, the camera and the estimator."""
    h = zlib.crc32(f"{seed}|{camera.key()}|{pricing_key}".encode())
    return (h % 1_000_003) / 1_000_003.0


# -- one camera -------------------------------------------------------------------------------------------
@dataclass
class _Design:
    """What every setting of one camera shares: blocks, the sample, the reference there."""

    W: int
    H: int
    B: int  # block side (display pixels)
    nbx: int
    nby: int
    pad: int
    aux_size: tuple[int, int]
    aux_reference: np.ndarray  # display-transformed auxiliary reference frame
    pi: np.ndarray  # inclusion probability of every block (row-major)
    sampled: np.ndarray  # sampled block indices
    regions: dict[int, tuple[int, int, int, int]]  # sampled block -> (x0, y0, x1, y1) block + margin
    counts: np.ndarray  # per block: pixels whose SSIM the frame's mean counts
    interior: int  # pixels whose SSIM the frame's mean counts
    reference: dict[int, np.ndarray]  # sampled block -> display-transformed reference over its region
    #: the reference's sampled tiles: counters, histograms, their blocks, and its traced size
    reference_tiles: tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int]] | None = None


def _display_cameras(camera: CameraSpec, pricing: DisplayPricing) -> tuple[Any, Any]:
    aw = max(8, round(camera.width / pricing.aux_divisor))
    ah = max(8, round(camera.height / pricing.aux_divisor))
    aux = dataclasses.replace(camera, width=aw, height=ah)
    return camera.to_camera(), aux.to_camera()


#: Tile side of the auxiliary frames: small, so that their tiles fall into single blocks.
AUX_TILE = 4


class _Renderer:
    """The scene and thread count one pricing task renders with."""

    def __init__(self, scene: Any, threads: int | None) -> None:
        self.scene, self.threads = scene, threads

    def frame(self, camera: Any, settings: Any) -> Any:
        return sim_core.render(self.scene, camera, settings, threads=self.threads)

    def aux_frame(self, camera: Any, settings: Any) -> Any:
        """An auxiliary frame: small tiles, so that per-tile counters say where the work is."""
        return self.frame(camera, dataclasses.replace(settings, tile_size=AUX_TILE))

    def windows(self, camera: Any, settings: Any, blocks: Sequence[int], d: _Design
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
        """Trace what the sampled ``blocks`` need at display resolution: the traced-resolution canvas
        (only the needed pixels filled), and the counters and histograms of the tiles whose centre lies
        in a sampled block (rows), with those tiles' blocks."""
        s = settings
        w, h = sim_core.render_size(camera, s)
        ts = s.tile_size
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
        owner = _block_of(cx.ravel(), cy.ravel(), d.W / w, d.H / h, d.B, d.nbx, d.nby).reshape(nty, ntx)
        counted = np.isin(owner, np.asarray(blocks))
        per_pixel = s.mode in ("1spp", "fsaa")
        tiles = counted.copy()
        if not per_pixel:  # adaptive modes: every needed pixel's whole tile
            tiles |= np.add.reduceat(np.add.reduceat(need.astype(np.int32), np.arange(0, h, ts), axis=0),
                                     np.arange(0, w, ts), axis=1) > 0
        canvas = np.zeros((h, w, 3), dtype=np.float32)
        covered = np.zeros((h, w), dtype=bool)
        rows_c: list[np.ndarray] = []
        rows_h: list[np.ndarray] = []
        rows_b: list[np.ndarray] = []
        for tx0, ty0, tx1, ty1 in _rects(tiles):
            x, y = tx0 * ts, ty0 * ts
            win = (x, y, min(tx1 * ts, w) - x, min(ty1 * ts, h) - y)
            r = sim_core.render_window(self.scene, camera, s, win, threads=self.threads)
            canvas[y:y + win[3], x:x + win[2]] = r.image
            covered[y:y + win[3], x:x + win[2]] = True
            keep = np.asarray([counted[t["y0"] // ts, t["x0"] // ts] for t in r.tile_stats], dtype=bool)
            if keep.any():
                rows_c.append(r.tile_counters[keep])
                rows_h.append(r.tile_histograms[keep])
                rows_b.append(np.asarray([owner[t["y0"] // ts, t["x0"] // ts] for t in r.tile_stats])[keep])
        if per_pixel:  # the margins' pixels alone (a per-pixel mode has the frame's pixels anywhere)
            for x0, y0, x1, y1 in _rects(need & ~covered):
                r = sim_core.render_window(self.scene, camera, s, (x0, y0, x1 - x0, y1 - y0),
                                           threads=self.threads)
                canvas[y0:y1, x0:x1] = r.image
                covered[y0:y1, x0:x1] = True
        if not covered[need].all():
            raise RuntimeError("tile estimator: a needed pixel was not traced")
        nc = len(COUNTER_NAMES)
        return (canvas, np.concatenate(rows_c) if rows_c else np.zeros((0, nc), np.uint64),
                np.concatenate(rows_h) if rows_h else np.zeros((0, 25), np.uint64),
                np.concatenate(rows_b) if rows_b else np.zeros(0, np.int64), (w, h))


def _srgb(image: np.ndarray) -> np.ndarray:
    return linear_to_srgb(image)


def _aux_measure(renderer: _Renderer, aux_cam: Any, settings: Any, aux_reference: np.ndarray, d: _Design
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """Per-block auxiliary error sums (N,), counters (N, C) and histograms (N, 25) of one setting."""
    r = renderer.aux_frame(aux_cam, settings)
    n = d.nbx * d.nby
    ah, aw = aux_reference.shape[:2]
    e = 1.0 - ssim_map(aux_reference, _srgb(r.image))  # uniform window: a map of where they differ
    p = UNIFORM_WIN // 2
    yy, xx = np.mgrid[p:ah - p, p:aw - p]
    owner = _block_of(xx.ravel() + 0.5, yy.ravel() + 0.5, d.W / aw, d.H / ah, d.B, d.nbx, d.nby)
    x_err = np.bincount(owner, weights=np.maximum(e.ravel(), 0.0), minlength=n)
    return (x_err, *_counter_blocks(r, d), r)


def _probes(space: ParameterSpace) -> list[Indices]:
    """The space's cheapest setting and two on the way to the best (the paper's Min, Mid-Min and
    Max-Mid presets): where cheap settings err, for the size measure."""
    lo, hi = space.min_quality_indices(), space.max_quality_indices()
    return list(dict.fromkeys(tuple(round(a + f * (b - a)) for a, b in zip(lo, hi, strict=True))
                              for f in (0.0, 0.25, 0.75)))


def _design(renderer: _Renderer, camera: CameraSpec, space: ParameterSpace, pricing: DisplayPricing,
            metric: str) -> tuple[_Design, dict[Indices, tuple]]:
    """Blocks, size measure, sample and the reference over the sampled regions (with the auxiliary
    measures of the probes and the reference, which the caller may reuse)."""
    W, H = camera.width, camera.height
    B = pricing.block_for(W, H)
    nbx, nby = -(-W // B), -(-H // B)
    pad = _pad(metric)
    _full_cam, aux_cam = _display_cameras(camera, pricing)
    mq = space.max_quality_indices()
    ref_settings = space.to_settings(mq)
    aux_ref = renderer.aux_frame(aux_cam, ref_settings)
    aux_reference = _srgb(aux_ref.image)
    shell = _Design(W, H, B, nbx, nby, pad, (aux_cam.width, aux_cam.height), aux_reference, np.zeros(0),
                    np.zeros(0, np.int64), {}, np.zeros(0), 0, {})
    n = nbx * nby
    measures: dict[Indices, tuple] = {}
    ref_cnt = _counter_blocks(aux_ref, shell)[0][:, _COL["rays_total"]]
    err = np.zeros(n)
    for probe in _probes(space):
        if probe == mq:
            continue
        m = _aux_measure(renderer, aux_cam, space.to_settings(probe), aux_reference, shell)
        measures[probe] = m
        if m[0].sum() > 0:
            err += m[0] / m[0].sum()
    size = 0.2 / n + 0.2 * (ref_cnt / ref_cnt.sum() if ref_cnt.sum() > 0 else 1.0 / n)
    size = size + (0.6 * err / err.sum() if err.sum() > 0 else 0.6 / n)
    pi = inclusion_probabilities(size, pricing.fraction * n)
    sampled = systematic_sample(pi, serpentine(nbx, nby), sample_start(pricing.seed, camera,
                                                                         pricing.key(metric)))
    counts = np.zeros(n)
    for b in range(n):
        bx, by = b % nbx, b // nbx
        cw = max(0, min((bx + 1) * B, W - pad) - max(bx * B, pad))
        ch = max(0, min((by + 1) * B, H - pad) - max(by * B, pad))
        counts[b] = cw * ch
    regions = {}
    for b in sampled.tolist():
        bx, by = b % nbx, b // nbx
        regions[b] = (max(0, bx * B - pad), max(0, by * B - pad), min(W, (bx + 1) * B + pad),
                      min(H, (by + 1) * B + pad))
    d = dataclasses.replace(shell, pi=pi, sampled=sampled, regions=regions, counts=counts,
                            interior=int(max(0, W - 2 * pad) * max(0, H - 2 * pad)))
    measures[mq] = (np.zeros(n), *_counter_blocks(aux_ref, d), aux_ref)
    return d, measures


def _counter_blocks(result: Any, d: _Design) -> tuple[np.ndarray, np.ndarray]:
    """Per-block sums of a render's per-tile counters (N, C) and histograms (N, 25)."""
    tb = _tile_blocks(result, (d.W, d.H), d.B, d.nbx, d.nby)
    cnt = np.zeros((d.nbx * d.nby, len(COUNTER_NAMES)))
    np.add.at(cnt, tb, result.tile_counters.astype(np.float64))
    hist = np.zeros((d.nbx * d.nby, 25))
    np.add.at(hist, tb, result.tile_histograms.astype(np.float64))
    return cnt, hist


def _patches(canvas: np.ndarray, size: tuple[int, int], d: _Design, blocks: Sequence[int]
             ) -> dict[int, np.ndarray]:
    """Display-transformed display pixels over every sampled block's region (bit for bit the whole
    frame's upsampling)."""
    out = {}
    for b in blocks:
        out[b] = _srgb(upsample_bilinear(canvas, d.H, d.W, window=d.regions[b]))
    return out


def _ratio(y: np.ndarray, x_sample: np.ndarray, x_total: float, pi: np.ndarray) -> tuple[float, float]:
    """Ratio estimate of a total (and its approximate standard error) from sampled values ``y``, their
    auxiliary values and the auxiliary total; Horvitz-Thompson where the auxiliary carries nothing."""
    ht_y = float(np.sum(y / pi))
    ht_x = float(np.sum(x_sample / pi))
    if x_total > 0 and ht_x > 0:
        rate = ht_y / ht_x
        est = x_total * rate
        resid = y - rate * x_sample
    else:
        est, resid = ht_y, y
    loose = pi < 1.0
    k = int(loose.sum())
    if k < 2:
        return est, 0.0
    t = k * resid[loose] / pi[loose]
    se = math.sqrt(float(np.sum((t - t.mean()) ** 2)) / (k * (k - 1)))
    return est, se


def _estimate(d: _Design, sample_err: np.ndarray | None, sample_cnt: np.ndarray, sample_hist: np.ndarray,
              sample_owner: np.ndarray, aux: tuple, render_size: tuple[int, int]
              ) -> tuple[float, float, dict[str, int], np.ndarray, float]:
    """(error, its standard error, counters, histogram, relative standard error of rays_total)."""
    blocks = d.sampled
    pi = d.pi[blocks]
    x_err, x_cnt, x_hist = aux[0], aux[1], aux[2]
    if sample_err is None:  # the reference itself
        error, se_err = 0.0, 0.0
    else:
        total, se = _ratio(sample_err, x_err[blocks], float(x_err.sum()), pi)
        error = min(max(total / d.interior, 0.0), 1.0) if d.interior else 0.0
        se_err = se / d.interior if d.interior else 0.0
    y_cnt = np.zeros((len(blocks), sample_cnt.shape[1]))
    pos = {int(b): i for i, b in enumerate(blocks)}
    np.add.at(y_cnt, [pos[int(b)] for b in sample_owner], sample_cnt.astype(np.float64))
    y_hist = np.zeros((len(blocks), 25))
    np.add.at(y_hist, [pos[int(b)] for b in sample_owner], sample_hist.astype(np.float64))
    counters: dict[str, int] = {}
    se_rays = 0.0
    for i, name in enumerate(COUNTER_NAMES):
        est, se = _ratio(y_cnt[:, i], x_cnt[blocks, i], float(x_cnt[:, i].sum()), pi)
        counters[name] = max(0, round(est))
        if name == "rays_total" and est > 0:
            se_rays = se / est
    w, h = render_size
    counters["pixels"] = w * h
    counters["framebuffer_bytes"] = 4 * w * h
    hist = np.zeros(25)
    for i in range(25):
        hist[i] = max(0.0, _ratio(y_hist[:, i], x_hist[blocks, i], float(x_hist[:, i].sum()), pi)[0])
    hist_total = hist.sum()
    if hist_total > 0:  # the histogram counts the closest-hit comparisons
        hist *= counters["closest_hit_comparisons"] / hist_total
    return error, se_err, counters, np.round(hist).astype(np.int64), se_rays


_DESIGNS: LRUCache[tuple[str, ...], tuple[_Design, dict]] = LRUCache(4)


def price_camera(scene: Any, camera: CameraSpec, settings: Sequence[Indices], space: ParameterSpace, *,
                 profile: str, fps: float, metric: str, pricing: DisplayPricing,
                 threads: int | None = None, scene_hash: str | None = None) -> list[Evaluation]:
    """Error, power and frame time of every setting at ``camera`` (display resolution), priced as
    ``pricing`` says; the maximum-quality reference is rendered once for all of them."""
    renderer = _Renderer(scene, threads)
    mq = space.max_quality_indices()
    if pricing.key(metric).startswith("full"):
        ref = renderer.frame(camera.to_camera(), space.to_settings(mq))
        out = []
        for idx in settings:
            r = ref if tuple(idx) == mq else renderer.frame(camera.to_camera(), space.to_settings(idx))
            err = 0.0 if tuple(idx) == mq else image_error(metric, ref.image, r.image)
            power, frame_time, breakdown = _price(r, profile, fps)
            breakdown.update(_labels(camera, r.render_resolution, fraction=1.0))
            out.append(Evaluation(err, power, frame_time, breakdown))
        return out
    key = (scene_hash or str(scene.content_hash), camera.key(), pricing.key(metric),
           repr(sorted(space.fields_of(mq).items())), repr(_probes(space)))
    cached = _DESIGNS.get(key)
    if cached is None:
        cached = _design(renderer, camera, space, pricing, metric)
        _DESIGNS.put(key, cached)
    d, probe_measures = cached
    full_cam, aux_cam = _display_cameras(camera, pricing)
    blocks = d.sampled.tolist()
    if d.reference_tiles is None:
        canvas, cnt, hist, owner, size = renderer.windows(full_cam, space.to_settings(mq), blocks, d)
        d.reference.update(_patches(canvas, size, d, blocks))
        d.reference_tiles = (cnt, hist, owner, size)
    gaussian = metric == "ssim_gaussian"
    out = []
    traced_pixels = sum((r[2] - r[0]) * (r[3] - r[1]) for r in d.regions.values())
    for idx in settings:
        idx = tuple(int(i) for i in idx)
        s = space.to_settings(idx)
        if idx == mq:
            cnt, hist, owner, size = d.reference_tiles
            y_err = None
        else:
            canvas, cnt, hist, owner, size = renderer.windows(full_cam, s, blocks, d)
            test = _patches(canvas, size, d, blocks)
            y_err = np.asarray([d.counts[b] * (1.0 - ssim(d.reference[b], test[b], gaussian_weights=gaussian))
                                if d.counts[b] > 0 else 0.0 for b in blocks])
        aux = probe_measures.get(idx)
        if aux is None:
            aux = _aux_measure(renderer, aux_cam, s, d.aux_reference, d)
        error, se_err, counters, histogram, se_rays = _estimate(d, y_err, cnt, hist, owner, aux, size)
        est = SimpleNamespace(counters=counters, comparator_histogram=histogram, settings=s)
        power, frame_time, breakdown = _price(est, profile, fps)
        breakdown.update(_labels(camera, size, fraction=traced_pixels / (d.W * d.H)))
        breakdown.update({"display.se_error": se_err, "display.se_rays_rel": se_rays,
                          "display.blocks_sampled": float(len(blocks)),
                          "display.blocks_total": float(d.nbx * d.nby)})
        out.append(Evaluation(error, power, frame_time, breakdown))
    return out


def _labels(camera: CameraSpec, size: tuple[int, int], *, fraction: float) -> dict[str, float]:
    return {"display.width": float(camera.width), "display.height": float(camera.height),
            "display.traced_width": float(size[0]), "display.traced_height": float(size[1]),
            "display.pixel_fraction": float(fraction)}


# -- the driver: through the evaluation cache and the executor ----------------------------------------------
@dataclass(frozen=True)
class _TaskContext:
    """What every pricing task of a batch shares (sent once per worker and batch)."""

    scene: SceneHandle
    space: ParameterSpace
    profile: str
    fps: float
    metric: str
    pricing: DisplayPricing
    threads: int | None


def _price_task(ctx: _TaskContext, item: tuple[CameraSpec, list[Indices]]) -> list[Evaluation]:
    camera, settings = item
    return price_camera(ctx.scene.get(), camera, settings, ctx.space, profile=ctx.profile, fps=ctx.fps,
                        metric=ctx.metric, pricing=ctx.pricing, threads=ctx.threads,
                        scene_hash=ctx.scene.content_hash)


class DisplayPricer:
    """Prices (display-resolution camera, settings) at display resolution for an :class:`Evaluator`'s
    scene, space, profile, frame rate and metric, through its evaluation cache and executor: one task
    per camera (its reference is traced once for all its settings), cached per setting under a key
    that names the display resolution and the estimator."""

    def __init__(self, evaluator: Evaluator, pricing: DisplayPricing) -> None:
        self.ev = evaluator
        self.pricing = pricing
        ctx = evaluator.ctx
        self.ctx = _TaskContext(evaluator.scene, evaluator.space, ctx.profile, ctx.fps, ctx.metric, pricing,
                                ctx.threads)
        self.metric_key = (f"{ctx.metric}:{PIPELINE_VERSION}:{space_fingerprint(evaluator.space)}:"
                           f"display={pricing.key(ctx.metric)}")
        self.evaluations = 0  # settings actually priced
        self.cameras = 0  # camera tasks run

    def _key(self, camera: CameraSpec) -> CacheKey:
        return CacheKey(self.ev.scene.content_hash, camera.key(), self.metric_key, self.ctx.profile,
                        camera.width, camera.height, self.ctx.fps)

    def price(self, requests: Sequence[tuple[CameraSpec, Sequence[Indices]]]) -> list[list[Evaluation]]:
        """Evaluations of every request's settings, in order; cached ones are not priced again."""
        space = self.ev.space
        reqs = [(cam, [tuple(int(i) for i in x) for x in xs]) for cam, xs in requests]
        found: dict[tuple[str, int], Evaluation] = {}
        todo: dict[str, tuple[CameraSpec, list[Indices]]] = {}
        for cam, xs in reqs:
            packs = {space.pack(x): x for x in xs}
            hit = self.ev.cache.get_many(self._key(cam), list(packs))
            self.ev.cache_hits += len(hit)
            for p, e in hit.items():
                found[(cam.key(), p)] = e
            missing = [x for p, x in packs.items() if p not in hit and (cam.key(), p) not in found]
            if missing:
                entry = todo.setdefault(cam.key(), (cam, []))
                entry[1].extend(x for x in missing if x not in entry[1])
        if todo:
            items = list(todo.values())
            results = self.ev.executor.map(_price_task, self.ctx, items)
            self.cameras += len(items)
            for (cam, xs), evs in zip(items, results, strict=True):
                pairs = [(space.pack(x), e) for x, e in zip(xs, evs, strict=True)]
                self.evaluations += len(pairs)
                self.ev.evaluations += len(pairs)
                for p, e in pairs:
                    found[(cam.key(), p)] = e
                self.ev.cache.put_many(self._key(cam), pairs)
        return [[found[(cam.key(), space.pack(x))] for x in xs] for cam, xs in reqs]
