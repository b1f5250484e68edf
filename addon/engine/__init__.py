"""The Render Budget GPU render engine: its properties, the engine (final renders and the viewport) and
its Render Properties panels."""

from __future__ import annotations

from . import panels, properties, render

_MODULES = (properties, render, panels)


def register() -> None:
    done = []
    try:
        for module in _MODULES:
            module.register()
            done.append(module)
    except Exception:
        for module in reversed(done):
            module.unregister()
        raise


def unregister() -> None:
    for module in reversed(_MODULES):
        module.unregister()
