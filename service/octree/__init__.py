"""Adaptive octree of camera samples along the path (power-budget paper, sec. 4.2, 5.2 and 5.3), in
separate pieces with one interface:

- :mod:`.lattice`: the root cube around the path, nodes, corners shared between nodes, and the
  frontier of every (corner, view); it writes the runtime store;
- :mod:`.search`: the lock-step search scheduler: the Pareto frontiers of many cameras at once (NSGA-II
  or enumeration), every generation of every camera one batch for the executor; progress and
  cancellation;
- two camera-sampling strategies behind :class:`~.builder.CameraSampling` (``build()``,
  ``store_cameras(used)``): :mod:`.view_cubes` (the paper's six views per corner, split where
  neighbouring frontiers differ; ``view_sampling`` "axis" or "aimed") and :mod:`.path_samples` (the
  path's own cameras on a lattice refined by viewing distance; "path", the default);
- :mod:`.builder`: :class:`OctreeBuilder` puts them together.

A camera sample is rendered with the path's vertical field of view and aspect at the evaluation
resolution. Seeds derive from the run seed and the camera, and the evaluation cache answers every
repeated render, so a rerun after an interruption replays the same decisions and resumes where it
stopped.

Adding a sampling strategy: a class with ``__init__(lattice, search, config, path)``, ``build()`` and
``store_cameras(used)``, registered in ``builder.STRATEGIES`` and named in
``service.options.VIEW_SAMPLING``.
"""

from __future__ import annotations

from .builder import CameraSampling, OctreeBuilder, OctreeConfig, PathFrames
from .lattice import CUBE_EDGES, N_VIEWS, FrontierRecord, Lattice, densify, root_cube
from .path_samples import PathSampling
from .search import Cancelled, Progress, Search
from .view_cubes import ViewCubeSampling, aimed_directions, frontier_distance

__all__ = [
    "CUBE_EDGES", "N_VIEWS", "CameraSampling", "Cancelled", "FrontierRecord", "Lattice", "OctreeBuilder",
    "OctreeConfig", "PathFrames", "PathSampling", "Progress", "Search", "ViewCubeSampling",
    "aimed_directions", "densify", "frontier_distance", "root_cube",
]
