"""Which settings the render engine uses for a frame: the store's choice under the scene's budget, or the
artist's manual quality settings, and the manual settings' Blender properties.

The manual settings are every value a job may search (``service.params.renderable_space()``): one
property per parameter whose items are that parameter's values, so the engine can render every setting
a store names and never offers one the renderer does not know. Pure (no bpy); ``addon/engine`` turns
:func:`quality_properties` into Blender properties and calls :class:`SettingsChooser` per frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from service import store as pareto_store
from service.options import check_query
from service.params import Indices, ParameterSpace, renderable_space

from .playback_logic import PlaybackDriver, frame_flags, validate_budget

# Labels and tooltips of the search space's parameters (their values come from the space itself).
_TEXT: dict[str, tuple[str, str]] = {
    "sampling": ("Sampling", "How many primary samples a pixel gets: adaptive undersampling traces one "
                             "reference per block and interpolates similar pixels, FSAA traces every "
                             "sub-sample"),
    "normal_threshold_deg": ("Similarity Threshold", "Largest angle between neighbouring normals that "
                                                     "still counts as similar (adaptive modes)"),
    "max_depth": ("Max Bounces", "Reflection and refraction depth of the ray tree"),
    "shadow_samples": ("Shadow Samples", "Shadow rays per light and sample (0 off, 1 hard shadows)"),
    "resolution_scale": ("Resolution Scale", "Fraction of the output resolution actually traced; the "
                                             "image is upscaled"),
    "env_filter": ("Environment Filter", "Cone filter of glossy environment lookups"),
    "ao_samples": ("AO Samples", "Ambient-occlusion rays per sample (0 off)"),
    "multirate": ("Multi-Rate", "Choose the reference spacing per tile from its similarity (adaptive "
                                "modes)"),
}
_ACRONYMS = {"fsaa": "FSAA", "1spp": "1 spp", "ao": "AO"}


def space() -> ParameterSpace:
    """Every value a store may name: what the engine's manual settings offer."""
    return renderable_space()


def value_identifier(value: Any) -> str:
    """The enum identifier of a parameter value (saved in .blend files: the value itself, not its
    position, so a reordered space keeps files meaning what they meant)."""
    return str(value)


def value_label(name: str, value: Any) -> str:
    if isinstance(value, bool):
        return "On" if value else "Off"
    if name.endswith("_scale") and isinstance(value, float):
        return f"{round(100 * value)} %"
    if name.endswith("_deg"):
        return f"{value:g}°"
    words = [_ACRONYMS.get(w, w) for w in str(value).split("_")]
    text = " ".join(words)
    return text[:1].upper() + text[1:]


@dataclass(frozen=True)
class QualityProperty:
    """What an enum property of one parameter needs: items are (identifier, label, description)."""

    name: str
    label: str
    description: str
    items: tuple[tuple[str, str, str], ...]
    default: str


def quality_properties(spc: ParameterSpace | None = None) -> tuple[QualityProperty, ...]:
    """One property per parameter of the space, defaulting to its maximum-quality value."""
    out = []
    for p in (spc or space()).parameters:
        label, description = _TEXT.get(p.name, (p.name.replace("_", " ").title(), ""))
        items = tuple((value_identifier(v), value_label(p.name, v), "") for v in p.values)
        out.append(QualityProperty(p.name, label, description, items, items[p.max_quality][0]))
    return tuple(out)


def manual_indices(identifiers: Mapping[str, str], spc: ParameterSpace | None = None) -> Indices:
    """Indices of the manual settings ({parameter: enum identifier}); parameters left out stay at
    maximum quality."""
    spc = spc or space()
    out = list(spc.max_quality_indices())
    for k, p in enumerate(spc.parameters):
        ident = identifiers.get(p.name)
        if ident is None:
            continue
        hits = [i for i, v in enumerate(p.values) if value_identifier(v) == ident]
        if not hits:
            raise ValueError(f"{ident!r} is not a value of {p.name!r}; values: {list(p.values)}")
        out[k] = hits[0]
    return tuple(out)


def pricing_fps(fps_target: float | None, scene_fps: float) -> float:
    """The frame rate a frame's power is priced at: ``fps_target``, the one the store lookup chose its
    settings for (the query's ``fps``, else the store's own), so the simulated power, the image
    metadata's ``fps`` and the CSV's ``fps_target`` agree with the lookup; ``scene_fps`` when the
    settings did not come from a lookup (None or 0: manual settings, maximum quality)."""
    return fps_target if fps_target else scene_fps


@dataclass(frozen=True)
class FrameSettings:
    """The settings of one frame and where they came from."""

    source: str  # "store" or "manual"
    indices: Indices  # into the engine's space
    predicted_power_w: float | None = None  # the store's prediction of these settings (None: manual)
    predicted_error: float | None = None
    target_indices: Indices | None = None  # the store's target before the temporal filter
    clamped: bool = False  # camera outside the store's space
    infeasible: bool = False  # nothing in the store meets the budget here
    note: str = ""  # why these settings, and what is flagged on this frame (playback_logic.frame_flags)
    fps_target: float | None = None  # the frame rate the store was looked up for (None: manual)
    meets_fps: bool | None = None  # the store says these settings keep up with it (None: unknown)
    priority: str = ""  # the lookup's (service.options.QUERY_PRIORITY); empty: manual settings
    #: the display the predictions hold for (service.store.FiguresSize.short: "640x360", "preview 64x36");
    #: empty: manual settings. Beside a render at another size, the simulated power is not comparable.
    predicted_for: str = ""

    @property
    def in_transition(self) -> bool:
        return self.target_indices is not None and self.target_indices != self.indices

    def pricing_fps(self, scene_fps: float) -> float:
        """The frame rate this frame's power is priced at (:func:`pricing_fps` of its lookup's target)."""
        return pricing_fps(self.fps_target, scene_fps)

    def values(self, spc: ParameterSpace | None = None) -> dict[str, Any]:
        return (spc or space()).values_of(self.indices)

    def render_settings(self, spc: ParameterSpace | None = None) -> Any:
        """``sim_core.RenderSettings`` of these indices."""
        return (spc or space()).to_settings(self.indices)

    def text(self, spc: ParameterSpace | None = None) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.values(spc).items())


@dataclass(frozen=True)
class Budget:
    mode: str  # "POWER" or "ERROR"
    value: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", validate_budget(self.mode, self.value))


class SettingsChooser:
    """The settings of each frame of one render job: the store's under the budget (temporal filter on
    scene time, frames in the order they are asked for) or, without a store or budget, the manual ones.

    One chooser per job: a still render starts a fresh filter (the store's target, reproducibly), an
    animation render steps one filter through its frames as playback would
    (:class:`addon.core.playback_logic.PlaybackDriver`, the same class the playback handler uses), under
    the lookup's query options ``query`` (``fps``, ``priority``: ``service.options.check_query``).
    """

    def __init__(self, manual: Indices, store: pareto_store.ParetoStore | None = None,
                 budget: Budget | None = None, period_s: float = 2.0,
                 spc: ParameterSpace | None = None, query: Mapping[str, Any] | None = None) -> None:
        self.space = spc or space()
        self.space.validate(manual)
        self.manual = tuple(manual)
        self.budget = budget
        self.query = check_query(query or {})
        if store is not None:
            store.check_fps(self.query["fps"])  # a target the store cannot answer fails the job up front
        self.driver = PlaybackDriver(store, period_s) if store is not None and budget is not None else None
        self.note = "" if self.driver else ("no budget set: manual settings" if store is not None
                                            else "no store: manual settings")

    @property
    def uses_store(self) -> bool:
        return self.driver is not None

    @property
    def store(self) -> pareto_store.ParetoStore | None:
        return self.driver.store if self.driver is not None else None

    def manual_settings(self) -> FrameSettings:
        return FrameSettings("manual", self.manual, note=self.note)

    def choose(self, matrix_world: Sequence[Sequence[float]], vfov: float, aspect: float,
               time_s: float) -> FrameSettings:
        if self.driver is None or self.budget is None:
            return self.manual_settings()
        if not (math.isfinite(vfov) and math.isfinite(aspect) and aspect > 0):
            raise ValueError(f"camera fov/aspect must be finite and positive, got {vfov}, {aspect}")
        frame = self.driver.step(matrix_world, vfov, aspect, time_s, self.budget.mode, self.budget.value,
                                 **self.query)
        store = self.driver.store
        target = self.space.indices_of(store.settings_of(frame.target_indices))
        flags = frame_flags(infeasible=frame.infeasible, slow=frame.meets_fps is False,  # the HUD's words
                            clamped=frame.clamped, in_transition=frame.in_transition,
                            fps_target=frame.fps_target, priority=frame.priority)
        return FrameSettings("store", self.space.indices_of(frame.active_settings),
                             frame.predicted_power_w, frame.predicted_error, target, frame.clamped,
                             frame.infeasible, "; ".join(flags), frame.fps_target, frame.meets_fps,
                             frame.priority, store.figures.short())
