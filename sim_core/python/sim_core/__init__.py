"""Simulator of a mobile ray-tracing GPU: tracer, adaptive sampling and energy model."""

from . import _core

__version__ = _core.__version__
__all__ = ["__version__"]
