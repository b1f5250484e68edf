"""Installing app handlers so that a reload of the extension never stacks a second copy."""

from __future__ import annotations

from collections.abc import Callable


def _same(h: object, fn: Callable) -> bool:
    return getattr(h, "__name__", None) == fn.__name__ and getattr(h, "__module__", None) == fn.__module__


def remove_handler(handlers: list, fn: Callable) -> None:
    """Remove every handler with fn's module and name (an old copy from before a reload included)."""
    for h in list(handlers):
        if _same(h, fn):
            handlers.remove(h)


def add_handler(handlers: list, fn: Callable) -> None:
    remove_handler(handlers, fn)
    handlers.append(fn)
