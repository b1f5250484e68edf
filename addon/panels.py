"""The "Power Budget" sidebar panel in the 3D viewport (drawing only; every action is an operator)."""

from __future__ import annotations

import bpy

from service import options as option_schema

from . import ops_optimize, preferences
from .playback import figures_of, flags_of


class RENDER_BUDGET_UL_parameters(bpy.types.UIList):
    """Parameter space: searchable parameters with their values; inert ones greyed out with the reason."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index=0):
        row = layout.row(align=True)
        row.active = not item.inert
        if item.inert:
            row.label(text=item.name, icon="CANCEL")
            row.label(text=item.reason)
        else:
            row.prop(item, "enabled", text="")
            row.label(text=item.name)
            row.prop(item, "values", text="")  # editable: the next job searches what it says


class VIEW3D_PT_render_budget(bpy.types.Panel):
    bl_label = "Render Budget"
    bl_idname = "VIEW3D_PT_render_budget"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Render Budget"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        props = context.scene.render_budget
        rt = context.window_manager.render_budget_runtime
        _draw_service(layout, context, props, rt)
        _draw_path_and_space(layout, props)
        draw_options(layout, props)
        _draw_budget(layout, props)
        _draw_job(layout, props, rt)
        if props.store_text is not None:
            _draw_results(layout, props, figures_of(context.scene))
        _draw_actions(layout, props)


def _draw_service(layout: bpy.types.UILayout, context: bpy.types.Context, props: bpy.types.PropertyGroup,
                  rt: bpy.types.PropertyGroup) -> None:
    """Where jobs run, the service's status and the hardware profile."""
    box = layout.box()
    row = box.row(align=True)
    remote = _remote(context)
    row.label(text="Jobs: remote service" if remote else "Jobs: this computer", icon="URL" if remote
              else "DESKTOP")
    row.operator("render_budget.service_start", text="Check", icon="CHECKMARK")
    if rt.service_status:
        for chunk in _wrap(rt.service_status, 48):
            box.label(text=chunk, icon="ERROR" if rt.service_status.startswith("error") else "NONE")
    box.prop_search(props, "profile", props, "profiles", text="Profile")


def _draw_path_and_space(layout: bpy.types.UILayout, props: bpy.types.PropertyGroup) -> None:
    """The camera path (recorded from the animation or the viewport) and the parameter space."""
    col = layout.column(align=True)
    col.label(text="Camera path")
    row = col.row(align=True)
    row.operator("render_budget.record_path_animation", icon="CAMERA_DATA")
    row.operator("render_budget.record_path_viewport", icon="REC")
    col.prop(props, "path_text", text="")
    col.prop(props, "frame_step")

    row = layout.row()
    row.label(text="Parameter space")
    row.operator("render_budget.analyze_scene", text="", icon="VIEWZOOM")
    layout.template_list("RENDER_BUDGET_UL_parameters", "", props, "parameters", props,
                         "parameters_index", rows=4)


def _draw_budget(layout: bpy.types.UILayout, props: bpy.types.PropertyGroup) -> None:
    col = layout.column(align=True)
    col.prop(props, "budget_mode", expand=True)
    col.prop(props, "power_budget" if props.budget_mode == "POWER" else "error_budget")
    col.prop(props, "filter_period")
    for opt in option_schema.QUERY_OPTIONS:  # the lookup's frame-rate target and priority
        col.prop(props, opt.name)


def _draw_job(layout: bpy.types.UILayout, props: bpy.types.PropertyGroup, rt: bpy.types.PropertyGroup
              ) -> None:
    """Optimize / cancel, the running job's progress or its failure, and how the simulated scene differs."""
    row = layout.row(align=True)
    row.scale_y = 1.4
    row.operator("render_budget.optimize", icon="PLAY")
    if ops_optimize.job_running():
        row.operator("render_budget.cancel_job", text="", icon="CANCEL")
    if rt.job_running or rt.job_status:
        failed = rt.job_status.startswith(("failed", "done, but"))
        if rt.job_running or not failed:
            layout.progress(factor=rt.job_progress, type="BAR", text=rt.job_status or "")
        if failed:  # the whole message, wrapped: it says what to do
            box = layout.box()
            for i, chunk in enumerate(_wrap(rt.job_status, 48)):
                box.label(text=chunk, icon="ERROR" if i == 0 else "BLANK1")
    if props.scene_notes:
        box = layout.box()
        box.label(text="The simulated scene differs:", icon="ERROR")
        for line in props.scene_notes.splitlines():
            for chunk in _wrap(line, 48):
                box.label(text=chunk)


def _draw_results(layout: bpy.types.UILayout, props: bpy.types.PropertyGroup, figures: str) -> None:
    """The loaded store's summary, playback switches and what playback applies at this frame (``figures``:
    the display its predictions hold for, :func:`~.playback.figures_of`)."""
    box = layout.box()
    box.label(text="Results", icon="INFO")
    for chunk in _wrap(props.summary, 48):
        box.label(text=chunk)
    box.prop(props, "playback_enabled")
    box.prop(props, "hud_enabled")
    if props.playback_status.startswith("error"):  # nothing applies: why, and no stale numbers
        for i, chunk in enumerate(_wrap(f"Playback {props.playback_status}", 48)):
            box.label(text=chunk, icon="ERROR" if i == 0 else "BLANK1")
    elif props.active_indices:
        rate = f" at {props.predicted_fps:.1f} fps" if props.predicted_fps > 0 else ""
        box.label(text=f"Power {props.predicted_power:.3f} W{rate}, "
                       f"error {props.predicted_error:.4f} ({figures})")
        for chunk in _wrap(props.active_settings, 48):
            box.label(text=chunk)
        for flag in flags_of(props, transition=False):  # the HUD's and the render engine's words
            for i, chunk in enumerate(_wrap(flag, 48)):
                box.label(text=chunk, icon="ERROR" if i == 0 else "BLANK1")


def _draw_actions(layout: bpy.types.UILayout, props: bpy.types.PropertyGroup) -> None:
    row = layout.row(align=True)
    row.operator("render_budget.preview", icon="RENDER_STILL")
    row.operator("render_budget.evaluate_path", icon="GRAPH")
    row.operator("render_budget.verify_store", icon="CHECKMARK")
    layout.prop(props, "report_frame_step")
    layout.operator("render_budget.load_store", icon="FILE")

def draw_options(layout: bpy.types.UILayout, props: bpy.types.PropertyGroup) -> None:
    """The optimiser's options, box by box as their schema groups them; an option that does not apply
    to the chosen camera samples is greyed out."""
    for group in option_schema.GROUPS:
        col = layout.column(align=True)
        col.label(text=group)
        for opt in option_schema.PUBLIC:
            if opt.group == group:
                row = col.row(align=True)
                row.active = not opt.modes or props.view_sampling in opt.modes
                row.prop(props, opt.name)


def _remote(context: bpy.types.Context) -> bool:
    try:
        return preferences.get(context).service_mode == "REMOTE"
    except RuntimeError:
        return False


def _wrap(text: str, width: int) -> list[str]:
    out, line = [], ""
    for word in (text or "").split():
        if line and len(line) + 1 + len(word) > width:
            out.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    if line:
        out.append(line)
    return out


classes = (RENDER_BUDGET_UL_parameters, VIEW3D_PT_render_budget)
register, unregister = bpy.utils.register_classes_factory(classes)
