"""Typed settings saved in the .blend (Scene) and runtime job state (WindowManager, not saved).

The optimiser's options and the store lookup's query options (``QUERY_OPTIONS``: the frame-rate target
and the priority playback, the render engine and Evaluate Path look the store up with) are scene
properties built from their one schema (``service.options``): same names, defaults, bounds and help as
the service's; an optional option (None: "derive it") shows 0. A .blend saved before an option existed
reads its default.
"""

from __future__ import annotations

from typing import Any

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from service import options as option_schema

from .core.playback_logic import FRAME_FLAGS


class RENDER_BUDGET_PG_parameter(bpy.types.PropertyGroup):
    """One parameter of the search space as the service reported it for this scene."""

    # `name` (built in) is the parameter's RenderSettings field name.
    values: StringProperty(  # type: ignore
        name="Values", description="Values the next job searches, comma separated (shadow "
        "rays and AO samples also take 2, 8 and 10, 12 between the default steps)")
    value_count: IntProperty(name="Count", min=0)  # type: ignore
    enabled: BoolProperty(name="Search", description="Include this parameter in the search", default=True)  # type: ignore
    inert: BoolProperty(name="Inert", description="Cannot change this scene's image or power")  # type: ignore
    reason: StringProperty(name="Reason")  # type: ignore


class RENDER_BUDGET_PG_profile(bpy.types.PropertyGroup):
    """A hardware profile name offered by the service (for the profile search field)."""


class RENDER_BUDGET_PG_scene(bpy.types.PropertyGroup):
    """Per-scene settings, inputs of a job and outputs of playback; all saved with the .blend."""

    profile: StringProperty(name="Profile", default="", description="Hardware profile (empty: default)")  # type: ignore
    profiles: CollectionProperty(type=RENDER_BUDGET_PG_profile)  # type: ignore
    parameters: CollectionProperty(type=RENDER_BUDGET_PG_parameter)  # type: ignore
    parameters_index: IntProperty()  # type: ignore

    # the optimiser's options are added from their schema below (option_properties)

    budget_mode: EnumProperty(  # type: ignore
        name="Budget",
        items=(("POWER", "Power (W)", "Least error under a power budget"),
               ("ERROR", "Error", "Least power under an error budget (1 - SSIM)")),
        default="ERROR",
    )
    power_budget: FloatProperty(name="Power budget (W)", default=2.0, min=0.0, soft_max=50.0)  # type: ignore
    error_budget: FloatProperty(name="Error budget", default=0.02, min=0.0, max=1.0, precision=4)  # type: ignore
    filter_period: FloatProperty(name="Filter time T (s)", default=2.0, min=0.0, soft_max=10.0,  # type: ignore
                                 description="Temporal filter: settings move to a new target over T seconds")
    frame_step: IntProperty(name="Record step", default=1, min=1, max=1000,  # type: ignore
                            description="Record every N-th frame of the camera animation")
    report_frame_step: IntProperty(name="Report step", default=5, min=1, max=1000,  # type: ignore
                                   description="Evaluate every N-th path frame in Evaluate Path")

    path_text: PointerProperty(type=bpy.types.Text, name="Camera path")  # type: ignore
    store_text: PointerProperty(type=bpy.types.Text, name="Pareto store")  # type: ignore
    scene_id: StringProperty(name="Scene id")  # type: ignore
    job_id: StringProperty(name="Job id")  # type: ignore
    store_id: StringProperty(name="Store id")  # type: ignore
    store_revision: IntProperty(name="Store revision",  # type: ignore
                                description="Bumped whenever the store text is replaced")
    summary: StringProperty(name="Summary")  # type: ignore
    scene_notes: StringProperty(  # type: ignore
        name="Scene notes",
        description="What the simulated scene approximates or leaves out of the scene as Blender renders it "
                    "(written when the scene is last sent to the simulator)")

    playback_enabled: BoolProperty(name="Drive settings on frame change", default=True)  # type: ignore
    hud_enabled: BoolProperty(name="Show HUD", default=True)  # type: ignore
    # Written by the playback handler on every frame change.
    active_settings: StringProperty(name="Active settings")  # type: ignore
    active_indices: StringProperty(name="Active indices")  # type: ignore
    target_indices: StringProperty(name="Target indices")  # type: ignore
    predicted_power: FloatProperty(name="Predicted power (W)")  # type: ignore
    predicted_error: FloatProperty(name="Predicted error", precision=4)  # type: ignore
    predicted_fps: FloatProperty(  # type: ignore
        name="Predicted frame rate (fps)",
        description="The frame rate the active settings reach on the store's hardware profile, at which the "
                    "predicted power is drawn (0: the store predates frame times)")
    target_fps: FloatProperty(  # type: ignore
        name="Frame-rate target (fps)",
        description="The frame rate the store was looked up for: the Frame rate option, else the store's")
    slower_than_fps: BoolProperty(  # type: ignore
        name="Slower than the frame-rate target",
        description="The active settings miss the frame-rate target here: no setting of the store keeps up "
                    "with it, or (Budget first) none within the budget does")
    clamped: BoolProperty(name=FRAME_FLAGS["clamped"][0].capitalize())  # type: ignore
    infeasible: BoolProperty(name=FRAME_FLAGS["infeasible"][0].capitalize())  # type: ignore
    playback_status: StringProperty(name="Playback status")  # type: ignore


def _option_property(opt: option_schema.Option) -> Any:
    """The Blender property of one optimiser option."""
    text = {"name": opt.label, "description": opt.help[:1].upper() + opt.help[1:]
            + (". 0 leaves it to that default" if opt.optional else "")}
    if opt.choices:
        labels = opt.choice_labels or opt.choices
        return EnumProperty(items=tuple((c, label, "") for c, label in zip(opt.choices, labels, strict=True)),
                            default=opt.default, **text)
    if opt.kind is bool:
        return BoolProperty(default=opt.default, **text)
    limits: dict[str, Any] = {"max": opt.maximum}
    limits["min"] = 0 if opt.optional else opt.minimum  # 0 stands for None
    limits = {k: v for k, v in limits.items() if v is not None}
    default = 0 if opt.default is None else opt.default
    if opt.kind is int:
        return IntProperty(default=default, **limits, **text)
    extra = {k: v for k, v in (("soft_max", opt.soft_max), ("precision", opt.precision)) if v is not None}
    return FloatProperty(default=default, **limits, **extra, **text)


def option_properties() -> dict[str, Any]:
    """Annotations for the public optimiser options and the query options (added to the scene settings
    group)."""
    return {o.name: _option_property(o) for o in (*option_schema.PUBLIC, *option_schema.QUERY_OPTIONS)}


RENDER_BUDGET_PG_scene.__annotations__.update(option_properties())


def option_values(props: Any, declared: tuple[option_schema.Option, ...] = option_schema.PUBLIC
                  ) -> dict[str, Any]:
    """The optimiser options (or other ``declared`` options) as set on a scene: 0 back to None for the
    optional ones, and floats to the 7 significant digits a Blender (single-precision) float property
    holds, so 0.05 stays 0.05."""
    out = {}
    for o in declared:
        value = getattr(props, o.name)
        if o.optional and value == 0:
            value = None
        elif o.kind is float:
            value = float(f"{value:.7g}")
        out[o.name] = value
    return out


def query_values(props: Any) -> dict[str, Any]:
    """The scene's store-lookup query options as ``ParetoStore.lookup`` keywords (``fps`` None: the
    store's own frame rate)."""
    return option_schema.check_query(option_values(props, option_schema.QUERY_OPTIONS))


_DECLARED = {**option_schema.BY_NAME, **option_schema.QUERY_BY_NAME}


def set_option(props: Any, name: str, value: Any) -> None:
    """Set one optimiser or query option on a scene (validated first: Blender would clamp silently)."""
    opt = _DECLARED[name]
    value = opt.check(value)
    setattr(props, name, 0 if value is None else value)


class RENDER_BUDGET_PG_runtime(bpy.types.PropertyGroup):
    """Job progress shown in the panel; runtime only (WindowManager data is not saved)."""

    job_running: BoolProperty()  # type: ignore
    job_progress: FloatProperty(min=0.0, max=1.0, subtype="FACTOR")  # type: ignore
    job_status: StringProperty()  # type: ignore
    service_status: StringProperty()  # type: ignore


classes = (RENDER_BUDGET_PG_parameter, RENDER_BUDGET_PG_profile, RENDER_BUDGET_PG_scene,
           RENDER_BUDGET_PG_runtime)
_register, _unregister = bpy.utils.register_classes_factory(classes)


def register() -> None:
    _register()
    bpy.types.Scene.render_budget = PointerProperty(type=RENDER_BUDGET_PG_scene)
    bpy.types.WindowManager.render_budget_runtime = PointerProperty(type=RENDER_BUDGET_PG_runtime)


def unregister() -> None:
    del bpy.types.WindowManager.render_budget_runtime
    del bpy.types.Scene.render_budget
    _unregister()
