"""The octree builder: the lattice (:mod:`.lattice`), the lock-step search scheduler (:mod:`.search`)
and one camera-sampling strategy (:class:`CameraSampling`: the paper's view cubes, :mod:`.view_cubes`,
or the path's own cameras, :mod:`.path_samples`) put together into a runtime store."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from service import options
from service.evaluation import Evaluator
from service.nsga import NSGAConfig
from service.params import ParameterSpace
from service.store import ParetoStore

from .lattice import Lattice, root_cube
from .path_samples import PathSampling
from .search import Progress, Search
from .view_cubes import ViewCubeSampling


@dataclass
class OctreeConfig:
    """Subdivision thresholds and search options of one octree build."""

    threshold_power_w: float
    threshold_error: float
    max_depth: int = 2
    min_depth: int = 0  # nodes on the path are split at least this deep, whatever their frontiers
    margin: float = 0.1  # fraction of a node's side added around it for the "path passes through" test
    pad_fraction: float = 0.1
    min_size: float = 1.0
    nsga: NSGAConfig = field(default_factory=NSGAConfig)
    exhaustive_limit: int = 512
    vfov: float = 0.6911
    width: int = 64
    height: int = 36
    # "axis": the six world axes; "aimed": see :func:`aimed_directions`; "path": see the module docstring
    view_sampling: str = "aimed"
    path_resolution: float = 0.25  # "path" sampling: leaf side <= this x the path's viewing distance there
    guard_frames: int = 2  # "path" sampling: extra path cameras of each sample its frontier is priced at
    path_stride: int = 4  # "path" sampling: a full search at every path_stride-th sample along the path
    warm_generations: int = 5  # "path" sampling: generations of the warm-started searches in between

    def __post_init__(self) -> None:
        options.check({name: getattr(self, name) for name in (
            "threshold_power_w", "threshold_error", "max_depth", "min_depth", "margin", "view_sampling",
            "path_resolution", "guard_frames")})


@dataclass
class PathFrames:
    """The camera path as the strategies read it: positions (N, 3), forward vectors and the points
    their central rays see (aimed and path sampling), world matrices, vfovs and aspects (path
    sampling)."""

    positions: np.ndarray
    forwards: np.ndarray | None = None
    targets: np.ndarray | None = None
    matrices: np.ndarray | None = None
    vfovs: np.ndarray | None = None
    aspects: np.ndarray | None = None


class CameraSampling(Protocol):
    """Where the camera samples go and which frontier each (corner, view) gets."""

    def build(self) -> None:
        """Grow the lattice and give every (corner, view) a frontier (measured or inherited)."""

    def store_cameras(self, used: list[int]) -> dict[str, Any]:
        """The store fields saying where the frontiers ``used`` (lattice frontier ids, in store
        order) were measured (``view_dirs`` or ``frontier_dirs`` / ``frontier_eyes``), if any."""


STRATEGIES: dict[str, type] = {"axis": ViewCubeSampling, "aimed": ViewCubeSampling, "path": PathSampling}


class OctreeBuilder:
    """Builds the octree and its frontiers for one scene and path."""

    def __init__(self, evaluator: Evaluator, space: ParameterSpace, path: PathFrames, config: OctreeConfig,
                 progress: Callable[[Progress], None] | None = None,
                 should_cancel: Callable[[], bool] | None = None) -> None:
        n = len(path.positions)
        path = PathFrames(
            np.asarray(path.positions, dtype=np.float64).reshape(-1, 3),
            None if path.forwards is None else np.asarray(path.forwards, np.float64),
            None if path.targets is None else np.asarray(path.targets, np.float64),
            None if path.matrices is None else np.asarray(path.matrices, np.float64),
            np.full(n, config.vfov) if path.vfovs is None else np.asarray(path.vfovs, np.float64).reshape(-1),
            (np.full(n, config.width / config.height) if path.aspects is None
             else np.asarray(path.aspects, np.float64).reshape(-1)))
        self.space = space
        self.cfg = config
        root_min, root_size = root_cube(path.positions, config.pad_fraction, config.min_size,
                                        rest_on_path=config.view_sampling != "axis")
        self.lattice = Lattice(root_min, root_size, config.max_depth)
        self.search = Search(evaluator, space, config.nsga, config.exhaustive_limit, progress, should_cancel)
        strategy = STRATEGIES[config.view_sampling]
        self.sampling: CameraSampling = strategy(self.lattice, self.search, config, path)

    @property
    def state(self) -> Progress:
        return self.search.state

    def run(self) -> None:
        self.sampling.build()

    def to_store(self, *, profile: str, fps: float, aspect: float, meta: dict) -> ParetoStore:
        """The runtime store: nodes in creation order (children consecutive), shared frontiers."""
        return self.lattice.store(self.space, vfov=self.cfg.vfov, aspect=aspect, profile=profile, fps=fps,
                                  meta=meta, cameras=self.sampling.store_cameras)
