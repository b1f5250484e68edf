"""Viewport HUD: active settings, predicted power (with the frame rate it is drawn at) and error against
the budget, the lookup's priority when it is "budget first", and the frames that miss the frame-rate
target (GUI sessions only).

Nothing here runs in background mode: there the draw handler is never added (blf.draw would segfault).
"""

from __future__ import annotations

import bpy

from .playback import figures_of, flags_of

_handle = None


def hud_lines(scene: bpy.types.Scene) -> list[tuple[str, tuple[float, float, float, float]]]:
    """Text lines and colours for the HUD (red when the prediction breaks the budget)."""
    props = scene.render_budget
    if props.store_text is None:
        return []
    ok = (1.0, 1.0, 1.0, 1.0)
    bad = (1.0, 0.35, 0.3, 1.0)
    if props.playback_status.startswith("error"):  # nothing applies: say why instead of stale numbers
        return [(f"Render Budget playback {props.playback_status}", bad)]
    if props.budget_mode == "POWER":
        over = props.predicted_power > props.power_budget
        budget = f"budget {props.power_budget:.2f} W"
    else:
        over = props.predicted_error > props.error_budget
        budget = f"budget e {props.error_budget:.4f}"
    if props.priority == "budget":
        budget += ", budget first"
    # the frame rate the power is drawn at (0: a store before frame times)
    rate = f" at {props.predicted_fps:.1f} fps" if props.predicted_fps > 0 else ""
    lines = [
        (f"Power {props.predicted_power:.3f} W{rate}   Error {props.predicted_error:.4f}   ({budget})   "
         f"[{figures_of(scene)}]",
         bad if over or props.infeasible else ok),
        (f"Settings: {props.active_settings}", ok),
    ]
    flags = flags_of(props, short=True)  # the panels' and the render engine's words, in short
    if flags:
        lines.append(("; ".join(flags), bad if props.infeasible else ok))
    return lines


def draw_hud() -> None:
    if bpy.app.background:  # never draw without a GPU context
        return
    # lazy: Blender's drawing modules, only usable with a GPU context (never in background mode)
    import blf
    import gpu
    from gpu_extras.batch import batch_for_shader

    scene = bpy.context.scene
    if scene is None or not scene.render_budget.hud_enabled:
        return
    lines = hud_lines(scene)
    if not lines:
        return
    font, size, step, x0, y0 = 0, 13, 18, 20, 40
    blf.size(font, size)
    width = max(blf.dimensions(font, text)[0] for text, _ in lines)
    x1, y1 = x0 - 8, y0 - 8
    x2, y2 = x0 + width + 8, y0 + step * (len(lines) - 1) + size + 6
    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    batch = batch_for_shader(shader, "TRIS", {"pos": ((x1, y1), (x2, y1), (x2, y2), (x1, y2))},
                             indices=((0, 1, 2), (0, 2, 3)))
    gpu.state.blend_set("ALPHA")
    shader.uniform_float("color", (0.0, 0.0, 0.0, 0.55))
    batch.draw(shader)
    gpu.state.blend_set("NONE")
    y = y0
    for text, colour in reversed(lines):
        blf.color(font, *colour)
        blf.position(font, x0, y, 0)
        blf.draw(font, text)
        y += step


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
