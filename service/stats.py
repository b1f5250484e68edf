"""How sure a measured share is: the reports' "budget kept on k of n frames" from a sample of frames.

A share from 12 or 24 frames says little on its own (11 of 12 is 92 %, yet consistent with a true 95 %),
so the verify report and the main job's target lines give the Wilson score interval beside it. Written
here, not taken from scipy, because the add-on's reports run in Blender's Python, which has no scipy
(tests hold it to ``scipy.stats.binomtest(...).proportion_ci(method="wilson")``).
"""

from __future__ import annotations

import math
import numbers

#: the two-sided 95 % normal quantile
Z95 = 1.959963984540054


def share_interval(hits: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval (two-sided, ``z`` standard deviations: 95 % by default) for the share
    of ``n`` frames of which ``hits`` kept their budget."""
    if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in (hits, n)):
        raise ValueError(f"hits and n must be integers, got {hits!r} and {n!r}")
    if not 0 <= hits <= n or n < 1:
        raise ValueError(f"need 0 <= hits <= n and n >= 1, got {hits} of {n}")
    if not (math.isfinite(z) and z > 0):
        raise ValueError(f"z must be positive and finite, got {z!r}")
    p, z2 = hits / n, z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n)) / denom
    return (0.0 if hits == 0 else max(0.0, centre - half), 1.0 if hits == n else min(1.0, centre + half))


def share_text(hits: int, n: int) -> str:
    """``11/12 (92 %; 95 % interval 65-99 %)``: a share with how sure it is."""
    lo, hi = share_interval(hits, n)
    return f"{hits}/{n} ({100 * hits / n:.0f} %; 95 % interval {100 * lo:.0f}-{100 * hi:.0f} %)"
