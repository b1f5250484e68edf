"""The engine's Render Properties (``Scene.render_budget_engine``): where a frame's settings come from,
the manual quality settings (one enum per parameter of the optimiser's search space, generated from
it), the viewport's resolution and the threads. The budget, the store and the hardware profile are the
scene's existing Render Budget settings (``Scene.render_budget``), shared with the optimiser."""

from __future__ import annotations

from typing import Any

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from ..core.engine_settings import quality_properties


class RENDER_BUDGET_PG_engine(bpy.types.PropertyGroup):
    """Render Budget GPU settings of a scene (saved with the .blend)."""

    settings_source: EnumProperty(  # type: ignore[valid-type]
        name="Settings",
        items=(("STORE", "Store", "Each frame gets the settings the optimised store picks for its camera "
                                  "under the budget; the manual settings apply when the scene has no store"),
               ("MANUAL", "Manual", "Every frame gets the manual quality settings below")),
        default="STORE",
    )
    viewport_scale: FloatProperty(  # type: ignore[valid-type]
        name="Viewport Resolution", default=0.5, min=0.05, max=1.0, subtype="FACTOR",
        description="Fraction of the viewport's pixels the Rendered shading traces at its finest level "
                    "(it starts at a quarter of that and refines)")
    measure_error: BoolProperty(  # type: ignore[valid-type]
        name="Measure Error", default=False,
        description="Also render each frame at maximum quality and write the error measured against it "
                    "(1 - SSIM, as the optimiser measures) into the metadata and the CSV, beside the "
                    "store's prediction. Renders take about twice as long or more")
    threads: IntProperty(  # type: ignore[valid-type]
        name="Threads", default=0, min=0, max=1024,
        description="Tracer threads (0: one per processor)")


def _enum(q: Any) -> Any:
    return EnumProperty(name=q.label, description=q.description, items=q.items, default=q.default)


# One property per parameter of the optimiser's space, named after it (generated, never re-declared).
RENDER_BUDGET_PG_engine.__annotations__.update({q.name: _enum(q) for q in quality_properties()})


def manual_identifiers(engine_props: Any) -> dict[str, str]:
    """{parameter: enum identifier} of the manual quality settings."""
    return {q.name: getattr(engine_props, q.name) for q in quality_properties()}


classes = (RENDER_BUDGET_PG_engine,)
_register, _unregister = bpy.utils.register_classes_factory(classes)


def register() -> None:
    _register()
    bpy.types.Scene.render_budget_engine = PointerProperty(type=RENDER_BUDGET_PG_engine)


def unregister() -> None:
    del bpy.types.Scene.render_budget_engine
    _unregister()
