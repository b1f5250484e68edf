"""The tile estimator's sampling design: blocks of the display frame, the size measure's inclusion
probabilities, a systematic PPS sample along a serpentine path, and what one camera's design holds."""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from service.evaluation import CameraSpec


def cover_rects(mask: np.ndarray) -> list[tuple[int, int, int, int]]:
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


def block_of(cx: np.ndarray, cy: np.ndarray, scale_x: float, scale_y: float, block: int, nbx: int,
              nby: int) -> np.ndarray:
    """Block index (row-major) of points (traced-frame pixels) mapped to display coordinates."""
    bx = np.clip(np.floor(cx * scale_x / block).astype(np.int64), 0, nbx - 1)
    by = np.clip(np.floor(cy * scale_y / block).astype(np.int64), 0, nby - 1)
    return by * nbx + bx



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


@dataclass
class CameraDesign:
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
