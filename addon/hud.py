"""Viewport HUD: active settings, predicted power and error against the budget (GUI sessions only).

Nothing here runs in background mode: there the draw handler is never added (blf.draw would segfault).
"""

from __future__ import annotations

import bpy

_handle = None


def hud_lines(scene: bpy.types.Scene) -> list[tuple[str, tuple[float, float, float, float]]]:
    """Text lines and colours for the HUD (red when the prediction breaks the budget)."""
    props = scene.power_budget
    if props.store_text is None:
        return []
    ok = (1.0, 1.0, 1.0, 1.0)
    bad = (1.0, 0.35, 0.3, 1.0)
    if props.budget_mode == "POWER":
        over = props.predicted_power > props.power_budget
        budget = f"budget {props.power_budget:.2f} W"
    else:
        over = props.predicted_error > props.error_budget
        budget = f"budget e {props.error_budget:.4f}"
    lines = [
        (f"Power {props.predicted_power:.3f} W   Error {props.predicted_error:.4f}   ({budget})",
         bad if over or props.infeasible else ok),
        (f"Settings: {props.active_settings}", ok),
    ]
    flags = [f for f, on in (("blending", props.playback_status == "blending"),
                             ("outside store", props.clamped), ("budget infeasible", props.infeasible)) if on]
    if flags:
        lines.append(("; ".join(flags), bad if props.infeasible else ok))
    return lines


def draw_hud() -> None:
    if bpy.app.background:  # never draw without a GPU context
        return
    import blf

    context = bpy.context
    scene = context.scene
    if scene is None or not scene.power_budget.hud_enabled:
        return
    font = 0
    blf.size(font, 13)
    y = 40
    for text, colour in reversed(hud_lines(scene)):
        blf.color(font, *colour)
        blf.position(font, 20, y, 0)
        blf.draw(font, text)
        y += 18


def register() -> None:
    global _handle
    if bpy.app.background or _handle is not None:
        return
    _handle = bpy.types.SpaceView3D.draw_handler_add(draw_hud, (), "WINDOW", "POST_PIXEL")


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None


def is_registered() -> bool:
    """Whether a draw handler is currently installed (tests check that unregister removes it)."""
    return _handle is not None
