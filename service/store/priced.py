"""Each frontier point's figures at every camera the frontier was priced at, and the prediction of what
a frame between those cameras measures.

A path-sampled frontier is priced at its sample camera and at up to ``guard_frames`` more cameras of the
path frames it serves, and it keeps each point's *worst* error, power and frame time over them
(:mod:`service.octree.path_samples`): a bound over those cameras, which the budget searches use, so a
point is chosen only when its worst figures keep the budget. As a prediction of one frame's figures the
worst one is biased: a frame next to the sample camera gets the figure of a guard camera far from it
(on the hall, ``desktop``, 320x180, it was most of the power-budget mode's 0.0049 mean |predicted -
measured| error: bench/RESULTS.md).

So a store may also keep every point's figures at each pricing camera (:class:`PricedFigures`), and
the lookup predicts a frame's error and power as their Shepard interpolation at the frame's camera
(:func:`shepard_weights`: weights 1 / d^2, the figure of a pricing camera the frame coincides with),
``d^2`` being the sampler's own camera dissimilarity (:func:`camera_dissimilarity`: squared eye
distance in units of the frames' median viewing distance plus squared difference of the unit view
directions; the sample camera is the group's medoid in it and the guards its farthest frames). An
interpolation lies between the cameras' figures, so the prediction never exceeds the bound the budget
was checked against. Stdlib + numpy only (the add-on carries it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Below this dissimilarity a frame is at a pricing camera: it gets that camera's figures.
SAME_CAMERA = 1e-12


def camera_dissimilarity(eye_a: Any, forward_a: Any, eye_b: Any, forward_b: Any, scale: float) -> Any:
    """How unlike two cameras are (numpy broadcasting over leading axes): squared eye distance over
    ``scale``^2 (the frames' viewing distance) plus squared difference of the unit view directions.
    The path sampler chooses its sample (the medoid) and guards (the farthest frames) by it, and the
    lookup interpolates the pricing cameras' figures by it."""
    ea, eb = np.asarray(eye_a, dtype=np.float64), np.asarray(eye_b, dtype=np.float64)
    fa, fb = np.asarray(forward_a, dtype=np.float64), np.asarray(forward_b, dtype=np.float64)
    return ((ea - eb) ** 2).sum(axis=-1) / float(scale) ** 2 + ((fa - fb) ** 2).sum(axis=-1)


def shepard_weights(costs: Sequence[float]) -> tuple[float, ...]:
    """Interpolation weights (non-negative, summing to 1) from squared distances ``costs``: 1 / cost
    normalised (Shepard's inverse distance weighting, power 2); all of it on the first camera whose
    cost is at most :data:`SAME_CAMERA`."""
    c = costs if isinstance(costs, list) else [float(v) for v in costs]
    if not c:
        raise ValueError("no cameras to weigh")
    if not (min(c) >= 0.0 and math.isfinite(sum(c))):
        raise ValueError("camera dissimilarities must be finite and >= 0")
    for k, v in enumerate(c):
        if v <= SAME_CAMERA:
            return tuple(1.0 if j == k else 0.0 for j in range(len(c)))
    inv = [1.0 / v for v in c]
    total = sum(inv)
    return tuple(v / total for v in inv)


@dataclass
class PricedFigures:
    """One frontier's figures at each of its ``K`` pricing cameras (the sample camera first): ``eyes``
    and unit ``forwards`` (K, 3), the dissimilarity's distance unit ``scale`` (the median viewing
    distance of the frames the frontier serves), and ``error`` / ``power_w`` (K, n) of the frontier's
    ``n`` points in frontier order (``packed``, the frontier's own settings). The frontier's stored
    figures are the worst over the cameras."""

    eyes: np.ndarray
    forwards: np.ndarray
    scale: float
    packed: np.ndarray
    error: np.ndarray
    power_w: np.ndarray
    _column: dict[int, tuple[tuple[float, ...], tuple[float, ...]]] = field(init=False, repr=False,
                                                                            compare=False)
    _cams: tuple[tuple[float, float, float, float, float, float], ...] = field(init=False, repr=False,
                                                                              compare=False)

    def __post_init__(self) -> None:
        self.eyes = np.asarray(self.eyes, dtype=np.float64).reshape(-1, 3)
        fw = np.asarray(self.forwards, dtype=np.float64).reshape(-1, 3)
        self.packed = np.asarray(self.packed, dtype=np.int64).reshape(-1)
        k, n = self.eyes.shape[0], self.packed.size
        self.error = np.asarray(self.error, dtype=np.float64).reshape(k, n)
        self.power_w = np.asarray(self.power_w, dtype=np.float64).reshape(k, n)
        self.scale = float(self.scale)
        if k < 1 or fw.shape != (k, 3):
            raise ValueError("priced figures need one eye and one forward per pricing camera")
        if not (np.all(np.isfinite(self.eyes)) and np.all(np.isfinite(fw))):
            raise ValueError("pricing cameras must be finite")
        norm = np.linalg.norm(fw, axis=1, keepdims=True)
        if np.any(norm < 1e-9):
            raise ValueError("pricing camera forwards must be non-zero")
        self.forwards = fw / norm
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError("the pricing cameras' distance scale must be positive and finite")
        if not (np.all(np.isfinite(self.error)) and np.all(np.isfinite(self.power_w))):
            raise ValueError("priced figures must be finite")
        # plain floats for the per-frame lookup (a few cameras: no numpy call per query)
        err, pw = self.error.T.tolist(), self.power_w.T.tolist()
        self._column = {int(p): (tuple(err[j]), tuple(pw[j])) for j, p in enumerate(self.packed.tolist())}
        self._cams = tuple((*e, *f) for e, f in zip(self.eyes.tolist(), self.forwards.tolist(), strict=True))

    @property
    def cameras(self) -> int:
        return int(self.eyes.shape[0])

    def weights(self, eye: Sequence[float], forward: Sequence[float]) -> tuple[float, ...]:
        """Each pricing camera's weight for a frame at ``eye`` looking along the unit ``forward``."""
        ex, ey, ez = eye.tolist() if isinstance(eye, np.ndarray) else eye
        fx, fy, fz = forward.tolist() if isinstance(forward, np.ndarray) else forward
        s2 = self.scale * self.scale
        costs = [((ex - a) * (ex - a) + (ey - b) * (ey - b) + (ez - c) * (ez - c)) / s2
                 + (fx - u) * (fx - u) + (fy - v) * (fy - v) + (fz - w) * (fz - w)
                 for a, b, c, u, v, w in self._cams]
        return shepard_weights(costs)

    def expected(self, weights: Sequence[float], packed: int) -> tuple[float, float] | None:
        """(error, power) of setting ``packed`` interpolated with ``weights`` (None: not a point of this
        frontier)."""
        col = self._column.get(int(packed))
        if col is None:
            return None
        if len(weights) != len(self._cams):
            raise ValueError("one weight per pricing camera")
        err, pw = col
        e = p = 0.0
        for k, w in enumerate(weights):
            e += w * err[k]
            p += w * pw[k]
        return e, p
