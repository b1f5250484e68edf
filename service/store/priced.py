"""Each frontier point's figures at every camera the frontier was priced at, and the prediction of what
a frame between those cameras measures.

A path-sampled frontier is priced at its sample camera and at up to ``guard_frames`` more cameras of the
path frames it serves (and at one of as many other passes of the path through it, and at as many of its
frames as lie beyond the guard radius from all those), and it keeps each
point's *worst* error, power and frame time over them (:mod:`service.octree.path_samples`): a bound over
those cameras, which the budget searches use, so a point is chosen only when its worst figures keep the
budget. As a prediction of one frame's figures the worst one is biased: a frame next to the sample
camera gets the figure of a guard camera far from it (on the hall, ``desktop``, 320x180, it was most of
the power-budget mode's 0.0049 mean |predicted - measured| error: bench/RESULTS.md).

So a store may also keep every point's figures at each pricing camera (:class:`PricedFigures`), and
the lookup predicts a frame's error and power as their Shepard interpolation at the frame's camera
(:func:`shepard_weights`: weights 1 / d^2, the figure of a pricing camera the frame coincides with),
``d^2`` being the sampler's own camera dissimilarity (:func:`camera_dissimilarity`: squared eye
distance in units of the frames' median viewing distance plus squared difference of the unit view
directions; the sample camera is the group's medoid in it and the guards its farthest frames). An
interpolation lies between the cameras' figures, so the prediction never exceeds the bound the budget
was checked against.

The figures may include each point's frame time at each pricing camera (``frame_time_s``; optional: a
store made before keeps none). The worst frame time over the cameras draws the frontier's stored tiers
(:mod:`.frontier`: a point slow at one guard camera is in the slow tier for every frame the frontier
serves); with per-camera frame times the lookup instead predicts each point's frame time at the frame's
camera by the same interpolation (:meth:`PricedFigures.frame_time`, the same weights) and draws the
frame's tiers from that prediction (:mod:`.lookup`): a point that keeps up at the sample camera and
misses the rate only at a far guard is a real-time point at frames near the sample. Stdlib + numpy only
(the add-on carries it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
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
    ``n`` points in frontier order (``packed``, the frontier's own settings), and optionally their frame
    times ``frame_time_s`` (K, n; None: not kept). The frontier's stored figures are the worst over the
    cameras."""

    eyes: np.ndarray
    forwards: np.ndarray
    scale: float
    packed: np.ndarray
    error: np.ndarray
    power_w: np.ndarray
    frame_time_s: np.ndarray | None = None
    _column: dict[int, tuple[int, tuple[float, ...], tuple[float, ...]]] = field(init=False, repr=False,
                                                                                 compare=False)
    #: per point (frontier order): its frame time at each camera, and the least and largest of them
    _times: tuple[tuple[tuple[float, ...], float, float], ...] = field(init=False, repr=False, compare=False)
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
        self._times = ()
        if self.frame_time_s is not None:
            self.frame_time_s = np.asarray(self.frame_time_s, dtype=np.float64).reshape(k, n)
            if not (np.all(np.isfinite(self.frame_time_s)) and np.all(self.frame_time_s >= 0)):
                raise ValueError("per-camera frame times must be finite and >= 0")
            self._times = tuple((tuple(col), min(col), max(col)) for col in self.frame_time_s.T.tolist())
        # plain floats for the per-frame lookup (a few cameras: no numpy call per query)
        err, pw = self.error.T.tolist(), self.power_w.T.tolist()
        self._column = {int(p): (j, tuple(err[j]), tuple(pw[j])) for j, p in enumerate(self.packed.tolist())}
        self._cams = tuple((*e, *f) for e, f in zip(self.eyes.tolist(), self.forwards.tolist(), strict=True))

    @property
    def cameras(self) -> int:
        return int(self.eyes.shape[0])

    @property
    def frame_times_known(self) -> bool:
        """Whether each point's frame time at each camera is kept (else only the worst, in the frontier)."""
        return self.frame_time_s is not None

    def frame_time(self, weights: Sequence[float], point: int) -> float:
        """The frame time of the frontier's ``point`` (its place in frontier order) interpolated with
        ``weights``, held within its cameras' least and largest frame time (the weights sum to 1 up to
        rounding): the prediction the lookup draws a frame's tiers from. Needs :attr:`frame_times_known`."""
        times, lo, hi = self._times[point]
        if len(weights) != len(times):
            raise ValueError("one weight per pricing camera")
        if lo == hi:  # every camera's the same (what the interpolation, held within them, gives)
            return lo
        t = 0.0
        for w, v in zip(weights, times):  # noqa: B905 (lengths checked)
            t += w * v
        return min(max(t, lo), hi)

    def frame_time_range(self, point: int) -> tuple[float, float]:
        """The least and largest frame time of the frontier's ``point`` over the cameras."""
        _, lo, hi = self._times[point]
        return lo, hi

    def weights(self, eye: Sequence[float], forward: Sequence[float]) -> tuple[float, ...]:
        """Each pricing camera's weight for a frame at ``eye`` looking along the unit ``forward``."""
        ex, ey, ez = eye.tolist() if isinstance(eye, np.ndarray) else eye
        fx, fy, fz = forward.tolist() if isinstance(forward, np.ndarray) else forward
        s2 = self.scale * self.scale
        costs = [((ex - a) * (ex - a) + (ey - b) * (ey - b) + (ez - c) * (ez - c)) / s2
                 + (fx - u) * (fx - u) + (fy - v) * (fy - v) + (fz - w) * (fz - w)
                 for a, b, c, u, v, w in self._cams]
        return shepard_weights(costs)

    def point(self, packed: int) -> int | None:
        """The place of setting ``packed`` in frontier order (None: not a point of this frontier)."""
        col = self._column.get(int(packed))
        return None if col is None else col[0]

    def expected(self, weights: Sequence[float], packed: int,
                 reprice: Callable[[float, float], float] | None = None) -> tuple[float, float] | None:
        """(error, power) of setting ``packed`` interpolated with ``weights`` (None: not a point of this
        frontier). ``reprice(power, frame time)``: each camera's power for another frame rate, applied
        at each camera with its own frame time before the interpolation (None: as priced; with no
        per-camera frame times, applied to the interpolated power with the frontier's worst frame time
        by the caller)."""
        col = self._column.get(int(packed))
        if col is None:
            return None
        if len(weights) != len(self._cams):
            raise ValueError("one weight per pricing camera")
        j, err, pw = col
        if reprice is not None and self._times:
            times = self._times[j][0]
            pw = tuple(reprice(p, t) for p, t in zip(pw, times, strict=True))
        e = p = 0.0
        for k, w in enumerate(weights):
            e += w * err[k]
            p += w * pw[k]
        return e, p
