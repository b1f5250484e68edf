"""Render Budget: power-optimal ray-tracing settings along a camera path, driven from Blender.

Extension entry point: only registers the submodules (each owns its classes and handlers). bpy is imported
lazily so that the pure package `core` can be imported and tested without Blender.
"""

from __future__ import annotations

import importlib

# Registration order matters: properties reference preferences-independent types, panels come last.
_MODULE_NAMES = (
    "preferences",
    "properties",
    "migration",
    "service_process",
    "camera_path",
    "playback",
    "hud",
    "ops_optimize",
    "ops_preview",
    "ops_report",
    "engine.properties",
    "engine.render",
    "engine.panels",
    "panels",
)


def _modules() -> list:
    return [importlib.import_module(f"{__package__}.{name}") for name in _MODULE_NAMES]


def register() -> None:
    registered = []
    try:
        for module in _modules():
            module.register()
            registered.append(module)
    except Exception:
        for module in reversed(registered):
            module.unregister()
        raise


def unregister() -> None:
    for module in reversed(_modules()):
        module.unregister()
