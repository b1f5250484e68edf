"""Helpers for the add-on tests: a real (small, hand-built) Pareto store, and loading the built extension."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

REPO_ROOT = Path(__file__).resolve().parent.parent
EXT_ID = "render_budget"
REPO_MODULE = "render_budget_dev"  # our own extension repository name: no clash with other tests' repos
EXT_MODULE = f"bl_ext.{REPO_MODULE}.{EXT_ID}"

sys.path.insert(0, str(REPO_ROOT / "tools"))
import build_extension  # noqa: E402

from service.store import Frontier, ParetoStore, StoredParameter, pack_indices  # noqa: E402

PARAMETERS = (
    StoredParameter("max_depth", (3, 2, 1, 0), 0),
    StoredParameter("resolution_scale", (1.0, 0.9, 0.8, 0.7), 0),
    StoredParameter("shadow_samples", (16, 4, 1, 0), 0),
)


def view_frontier(view: int, timed: bool = False) -> Frontier:
    """A frontier whose cheap end depends on the view, so lookups differ by camera direction; ``timed``:
    with frame times, the max-quality setting too slow for the store's 24 fps (so it is left out)."""
    pts = []
    for k in range(4):  # quality level k: 0 = max quality
        idx = [k, min(3, (k + view) % 4), k]
        power = 4.0 - 0.8 * k - 0.05 * view
        error = 0.0 if k == 0 else 0.004 * k * (1 + view)
        pts.append((pack_indices(idx), error, power))
    times = [0.1, 0.03, 0.02, 0.01] if timed else None
    return Frontier.from_points([p[0] for p in pts], [p[1] for p in pts], [p[2] for p in pts], times,
                                fps=24.0 if timed else None)


def synthetic_store(root_min: tuple[float, float, float] = (-10.0, -10.0, -10.0), size: float = 20.0,
                    timed: bool = False) -> ParetoStore:
    """One-leaf store (8 corners, 6 views each) with view-dependent frontiers (``timed``: with frame
    times, store format 4)."""
    corners = np.array([[(k & 1), (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], dtype=np.int64)
    frontiers = [view_frontier(v, timed) for v in range(6)]
    views = np.tile(np.arange(6, dtype=np.int64), (8, 1))
    return ParetoStore(parameters=PARAMETERS, root_min=np.asarray(root_min), root_size=size,
                       lattice_depth=0, children=np.array([-1]), corner_coords=corners, corner_views=views,
                       frontiers=frontiers,
                       vfov=0.69, aspect=16 / 9, profile="mobile", fps=24.0)


def stage_extension(tmp: Path) -> Path:
    """Stage the extension (with its vendored modules) under `tmp`; returns the repo folder."""
    build_extension.stage(tmp)
    return tmp


def enable_dev(bpy: Any, repo_dir: Path) -> Any:
    """Register `repo_dir` as a dev extension repo and enable the add-on from it."""
    import addon_utils

    prefs = bpy.context.preferences
    repo = next((r for r in prefs.extensions.repos if r.module == REPO_MODULE), None)
    if repo is None:
        prefs.extensions.repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=str(repo_dir),
                                   source="USER")
    elif repo_dir != Path() and repo.custom_directory != str(repo_dir):
        repo.custom_directory = str(repo_dir)
    return addon_utils.enable(EXT_MODULE, default_set=True, handle_error=_raise)


def disable_dev() -> None:
    import addon_utils

    addon_utils.disable(EXT_MODULE, default_set=True, handle_error=_raise)


def _raise(exc: BaseException) -> None:
    raise exc


def store_json(store: ParetoStore) -> str:
    text = store.to_json()
    json.loads(text)
    return text
