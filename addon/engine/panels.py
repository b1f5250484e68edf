"""Render Properties of the Render Budget GPU engine (as Cycles shows its samples and bounces): where
the settings come from, the quality settings the optimiser searches, the budget and the store, the
hardware profile, the viewport, and what the last frame cost. Drawing only.

Blender's own panels that apply to any engine (output, colour management, materials, lights, world)
list the engines they show for; the engine adds itself to those lists while it is registered."""

from __future__ import annotations

import bpy

from ..core.engine_settings import quality_properties
from ..playback import figures_of, flags_of
from . import render

# EEVEE panels that show what the engine translates (Principled BSDF surfaces, light and world
# settings); panels that list BLENDER_RENDER are engine-independent and added too.
_BORROWED = frozenset({"EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_surface",
                       "EEVEE_WORLD_PT_surface", "DATA_PT_EEVEE_light", "NODE_DATA_PT_EEVEE_light"})
_added: list[type] = []  # panels whose COMPAT_ENGINES this module extended (removed again on unregister)


class _EnginePanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {render.ENGINE_ID}  # noqa: RUF012 (Blender reads class attributes)

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return context.engine in cls.COMPAT_ENGINES

    def split_layout(self) -> bpy.types.UILayout:
        """The layout with labels left of their fields, as Blender's own Render Properties."""
        self.layout.use_property_split = True
        self.layout.use_property_decorate = False
        return self.layout


class RENDER_PT_render_budget_settings(_EnginePanel, bpy.types.Panel):
    bl_label = "Settings"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        eng, props = context.scene.render_budget_engine, context.scene.render_budget
        layout.row().prop(eng, "settings_source", expand=True)
        layout.prop(eng, "measure_error")
        if eng.settings_source == "STORE":
            if props.store_text is None:
                layout.label(text="No store yet: Optimize Power in the sidebar; manual settings apply",
                             icon="INFO")
            else:
                layout.label(text=f"Store: {props.store_text.name}", icon="TEXT")


class RENDER_PT_render_budget_quality(_EnginePanel, bpy.types.Panel):
    bl_label = "Quality"
    bl_parent_id = "RENDER_PT_render_budget_settings"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.split_layout()
        eng, props = context.scene.render_budget_engine, context.scene.render_budget
        chosen_by_store = eng.settings_source == "STORE" and props.store_text is not None
        if chosen_by_store:
            layout.label(text="The store picks these per frame; they apply without a store", icon="INFO")
        col = layout.column()
        col.active = not chosen_by_store
        for q in quality_properties():
            col.prop(eng, q.name)


class RENDER_PT_render_budget_budget(_EnginePanel, bpy.types.Panel):
    bl_label = "Budget"
    bl_parent_id = "RENDER_PT_render_budget_settings"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.split_layout()
        props = context.scene.render_budget
        layout.row().prop(props, "budget_mode", expand=True)
        layout.prop(props, "power_budget" if props.budget_mode == "POWER" else "error_budget")
        layout.prop(props, "filter_period")
        layout.prop(props, "store_text")
        if props.store_text is not None and props.active_settings:
            box = layout.box()
            box.label(text=f"This frame: {props.predicted_power:.3f} W, error {props.predicted_error:.4f} "
                           f"({figures_of(context.scene)})")
            for flag in flags_of(props, transition=False):  # the HUD's and the frame notes' words
                box.label(text=flag, icon="ERROR")


class RENDER_PT_render_budget_hardware(_EnginePanel, bpy.types.Panel):
    bl_label = "Hardware"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.split_layout()
        scene = context.scene
        props = scene.render_budget
        if len(props.profiles):
            layout.prop_search(props, "profile", props, "profiles", text="Profile")
        else:
            layout.prop(props, "profile")
        layout.label(text=f"Power at the scene's {scene.render.fps / scene.render.fps_base:g} fps, or the "
                          "lower rate a slow frame reaches")
        layout.prop(scene.render_budget_engine, "threads")


class RENDER_PT_render_budget_viewport(_EnginePanel, bpy.types.Panel):
    bl_label = "Viewport"
    bl_options = {"DEFAULT_CLOSED"}  # noqa: RUF012

    def draw(self, context: bpy.types.Context) -> None:
        self.split_layout().prop(context.scene.render_budget_engine, "viewport_scale")


class RENDER_PT_render_budget_film(_EnginePanel, bpy.types.Panel):
    bl_label = "Film"
    bl_options = {"DEFAULT_CLOSED"}  # noqa: RUF012

    def draw(self, context: bpy.types.Context) -> None:
        self.split_layout().prop(context.scene.render, "film_transparent", text="Transparent")


class RENDER_PT_render_budget_last(_EnginePanel, bpy.types.Panel):
    bl_label = "Last Render"
    bl_options = {"DEFAULT_CLOSED"}  # noqa: RUF012

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        last = render.last_frame
        if last is None:
            layout.label(text="Nothing rendered in this session yet")
            return
        out = last.output
        col = layout.column(align=True)
        col.label(text=f"Frame {last.frame}: {out.power_w:.3f} W simulated "
                       f"on {out.profile} at {out.achieved_fps:.3g} of {out.fps:g} fps")
        s = out.settings
        if s.predicted_power_w is not None:
            col.label(text=f"Store predicted {s.predicted_power_w:.3f} W, error {s.predicted_error:.4f} "
                           f"({s.predicted_for or 'size unknown'})")
        if out.measured_error is not None:
            col.label(text=f"Measured error {out.measured_error:.4f} (against maximum quality)")
        col.label(text=f"Frame time {1e3 * out.frame_time_s:.2f} ms "
                       f"({'meets' if out.deadline_met else 'misses'} the frame rate)")
        col.label(text=f"{s.source.capitalize()} settings: {s.text()}")
        if last.csv_path is not None:
            col.label(text=f"Per-frame CSV: {last.csv_path}")
        if out.scene_notes:
            col.label(text="The simulated scene differs from Blender's:", icon="ERROR")
            for line in out.scene_notes.split("; "):
                col.label(text=line)


classes = (RENDER_PT_render_budget_settings, RENDER_PT_render_budget_quality, RENDER_PT_render_budget_budget,
           RENDER_PT_render_budget_hardware, RENDER_PT_render_budget_viewport, RENDER_PT_render_budget_film,
           RENDER_PT_render_budget_last)


def _panels() -> list[type]:
    out, todo = [], list(bpy.types.Panel.__subclasses__())
    while todo:
        cls = todo.pop()
        todo.extend(cls.__subclasses__())
        out.append(cls)
    return out


def _borrow_panels() -> None:
    for cls in _panels():
        engines = getattr(cls, "COMPAT_ENGINES", None)
        if not isinstance(engines, set) or render.ENGINE_ID in engines:
            continue
        if "BLENDER_RENDER" in engines or cls.__name__ in _BORROWED:
            engines.add(render.ENGINE_ID)
            _added.append(cls)


def _return_panels() -> None:
    for cls in _added:
        cls.COMPAT_ENGINES.discard(render.ENGINE_ID)
    _added.clear()


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    _borrow_panels()


def unregister() -> None:
    _return_panels()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
