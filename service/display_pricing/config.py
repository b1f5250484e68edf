"""How store figures are priced at display resolution: the estimator's settings and what they key."""

from __future__ import annotations

import math
from dataclasses import dataclass

from service.metrics import GAUSS_SIGMA, GAUSS_TRUNCATE, UNIFORM_WIN

#: How store figures are priced at display resolution (``OptimizeConfig.display_estimator``).
ESTIMATORS = ("tiles", "full")
#: Bumped whenever the estimator's design changes (part of every cache key of its figures).
ESTIMATOR_VERSION = "1"
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


def ssim_margin(metric: str) -> int:
    """Half the SSIM window: the margin a block needs around it, and the border SSIM leaves out."""
    return int(GAUSS_TRUNCATE * GAUSS_SIGMA + 0.5) if metric == "ssim_gaussian" else UNIFORM_WIN // 2
