"""Typed settings saved in the .blend (Scene) and runtime job state (WindowManager, not saved)."""

from __future__ import annotations

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


class RENDER_BUDGET_PG_parameter(bpy.types.PropertyGroup):
    """One parameter of the search space as the service reported it for this scene."""

    # `name` (built in) is the parameter's RenderSettings field name.
    values: StringProperty(name="Values", description="Candidate values, comma separated")  # type: ignore
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

    threshold_power: FloatProperty(name="Power threshold (W)", default=0.05, min=0.0, soft_max=5.0,  # type: ignore
                                   description="Subdivide where neighbouring frontiers differ by more power")
    threshold_error: FloatProperty(name="Error threshold", default=0.01, min=0.0, max=1.0,  # type: ignore
                                   precision=4, description="Subdivide where frontiers differ by more error")
    camera_sampling: EnumProperty(  # type: ignore
        name="Camera samples",
        items=(("PATH", "Path cameras", "Measure each octree face the path looks up at the path camera most "
                "like the frames looking it up, on a lattice refined by viewing distance (recommended)"),
               ("AIMED", "Aimed view cubes", "The paper's six views per corner, aimed at what the path sees, "
                "split where neighbouring frontiers differ"),
               ("AXIS", "Axis view cubes", "The paper's six world-axis views per corner")),
        default="PATH",
    )
    path_resolution: FloatProperty(name="Path resolution", default=0.25, min=0.01, max=10.0,  # type: ignore
                                   description="Path cameras: octree leaves at most this times the viewing "
                                   "distance wide")
    guard_frames: IntProperty(name="Guard frames", default=2, min=0, max=8,  # type: ignore
                              description="Path cameras: also price each frontier at this many more path "
                              "cameras, keeping the worst error and power")
    max_depth: IntProperty(name="Max depth", default=6, min=0, max=8)  # type: ignore
    population: IntProperty(name="Population", default=24, min=4, max=1000)  # type: ignore
    generations: IntProperty(name="Generations", default=25, min=1, max=1000)  # type: ignore
    seed: IntProperty(name="Seed", default=0, min=0)  # type: ignore
    exhaustive_limit: IntProperty(name="Exhaustive up to", default=512, min=0,  # type: ignore
                                  description="Enumerate every setting when the space is this small")

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
    eval_width: IntProperty(name="Width", default=128, min=8, max=8192)  # type: ignore
    eval_height: IntProperty(name="Height", default=72, min=8, max=8192)  # type: ignore
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

    playback_enabled: BoolProperty(name="Drive settings on frame change", default=True)  # type: ignore
    hud_enabled: BoolProperty(name="Show HUD", default=True)  # type: ignore
    # Written by the playback handler on every frame change.
    active_settings: StringProperty(name="Active settings")  # type: ignore
    active_indices: StringProperty(name="Active indices")  # type: ignore
    target_indices: StringProperty(name="Target indices")  # type: ignore
    predicted_power: FloatProperty(name="Predicted power (W)")  # type: ignore
    predicted_error: FloatProperty(name="Predicted error", precision=4)  # type: ignore
    clamped: BoolProperty(name="Outside the store's space")  # type: ignore
    infeasible: BoolProperty(name="Budget infeasible")  # type: ignore
    playback_status: StringProperty(name="Playback status")  # type: ignore


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
