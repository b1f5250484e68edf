"""Render settings: the parameters the render-budget optimiser searches over (validated, immutable)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any, Literal

from . import _core

SamplingMode = Literal["1spp", "fsaa", "undersample", "supersample"]
EnvFilterMode = Literal["off", "box", "bartlett"]
MODES: tuple[str, ...] = ("1spp", "fsaa", "undersample", "supersample")
ENV_FILTERS: tuple[str, ...] = ("off", "box", "bartlett")


def _int(name: str, value: Any, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{name} must be an integer in {lo}..{hi}, got {value!r}")


def _float(name: str, value: Any, lo: float, hi: float) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if not lo <= value <= hi:
        raise ValueError(f"{name} must be in [{lo}, {hi}], got {value!r}")


@dataclass(frozen=True, kw_only=True)
class RenderSettings:
    """How to render a frame. Every field is one dimension of the optimiser's search space.

    mode: "1spp" (one ray per pixel), "fsaa" (block x block rays per pixel), "undersample" (reference
      pixels every `block` pixels, the rest interpolated where neighbours are similar, else traced),
      "supersample" (block x block sub-pixel grid, reference every `block` sub-pixels). The sub-pixel
      modes resolve their sub-samples with Cycles' default pixel filter (Blackman-Harris, 1.5 px wide).
    block: 2..4, the reference spacing / sub-pixel grid.
    normal_threshold_deg: similarity test angle; a negative value makes every test fail (full rate).
    max_depth: reflection/refraction bounces (0..4).
    shadow_samples: 0 = no shadow rays, 1 = hard shadows, N = N samples over each light's radius.
    resolution_scale: render at this fraction of the camera resolution (0.25..1), upscaled bilinearly.
    env_filter: glossy reflections of an environment map: "off" (one point-sampled ray in the lobe),
      "box" / "bartlett" (a summed-area-table filtered lookup over the lobe's cone); with filtering on,
      camera and mirror rays also read the map bilinearly instead of at the nearest texel.
    ao_samples: ambient-occlusion rays per hit (0 = unoccluded ambient light); the resolve pass denoises
      their estimate over neighbouring samples of the same surface.
    ao_distance: AO ray length in scene units; 0 = unbounded (the world's visibility: a closed room gets
      no sky light, as in Cycles); a positive length gives a classic ambient-occlusion look.
    multirate: per-tile block size chosen from the previous frame's similarity ratio
      (adaptive modes only; inert otherwise) with thresholds multirate_low < multirate_high (hysteresis).
    tile_size: tile edge in pixels, the unit of work and of the on-chip tile buffer.
    """

    mode: SamplingMode = "1spp"
    block: int = 2
    normal_threshold_deg: float = 20.0
    max_depth: int = 2
    shadow_samples: int = 1
    resolution_scale: float = 1.0
    env_filter: EnvFilterMode = "off"
    ao_samples: int = 0
    ao_distance: float = 0.0
    multirate: bool = False
    multirate_low: float = 0.5
    multirate_high: float = 0.85
    tile_size: int = 16

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        _int("block", self.block, 2, 4)
        if (
            isinstance(self.normal_threshold_deg, bool)
            or not isinstance(self.normal_threshold_deg, int | float)
            or not math.isfinite(self.normal_threshold_deg)
            or self.normal_threshold_deg > 180
        ):
            raise ValueError(
                f"normal_threshold_deg must be finite and <= 180, got {self.normal_threshold_deg!r}"
            )
        _int("max_depth", self.max_depth, 0, 4)
        _int("shadow_samples", self.shadow_samples, 0, 256)
        _float("resolution_scale", self.resolution_scale, 0.25, 1.0)
        if self.env_filter not in ENV_FILTERS:
            raise ValueError(f"env_filter must be one of {ENV_FILTERS}, got {self.env_filter!r}")
        _int("ao_samples", self.ao_samples, 0, 256)
        _float("ao_distance", self.ao_distance, 0.0, math.inf)
        if not isinstance(self.multirate, bool):
            raise ValueError(f"multirate must be a bool, got {self.multirate!r}")
        _float("multirate_low", self.multirate_low, 0.0, 1.0)
        _float("multirate_high", self.multirate_high, 0.0, 1.0)
        if not self.multirate_low < self.multirate_high:
            raise ValueError(
                f"multirate_low ({self.multirate_low}) must be below multirate_high ({self.multirate_high})"
            )
        _int("tile_size", self.tile_size, 4, 256)

    @classmethod
    def max_quality(cls) -> RenderSettings:
        """The reference configuration (error 0 by definition): FSAA 2x2 (Blackman-Harris pixel filter), 3
        bounces, 16 soft-shadow and 16 unbounded AO samples, full resolution, Bartlett-filtered glossy
        environment, no adaptive shortcuts."""
        return cls(
            mode="fsaa",
            block=2,
            max_depth=3,
            shadow_samples=16,
            resolution_scale=1.0,
            env_filter="bartlett",
            ao_samples=16,
            multirate=False,
        )

    @property
    def adaptive(self) -> bool:
        return self.mode in ("undersample", "supersample")

    def replace(self, **changes: Any) -> RenderSettings:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def to_native(self) -> Any:
        n = _core.NativeRenderSettings()
        n.mode = MODES.index(self.mode)
        n.block = self.block
        n.normal_threshold_deg = float(self.normal_threshold_deg)
        n.max_depth = self.max_depth
        n.shadow_samples = self.shadow_samples
        n.resolution_scale = float(self.resolution_scale)
        n.env_filter = ENV_FILTERS.index(self.env_filter)
        n.ao_samples = self.ao_samples
        n.ao_distance = float(self.ao_distance)
        n.multirate = self.multirate
        n.multirate_low = float(self.multirate_low)
        n.multirate_high = float(self.multirate_high)
        n.tile_size = self.tile_size
        n.validate()
        return n
