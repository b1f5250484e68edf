"""Render-budget service: evaluation, NSGA-II, octree, Pareto store, REST API."""

__version__ = "0.1.0"
