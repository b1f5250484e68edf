"""Helpers for the add-on tests: a real (small, hand-built) Pareto store, and loading the built extension."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
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


def view_frontier(view: int, timed: bool = False, slow: bool = False) -> Frontier:
    """A frontier whose cheap end depends on the view, so lookups differ by camera direction; ``timed``:
    with frame times, the max-quality setting too slow for the store's 24 fps (so it is left out);
    ``slow``: no setting keeps up with 24 fps."""
    pts = []
    for k in range(4):  # quality level k: 0 = max quality
        idx = [k, min(3, (k + view) % 4), k]
        power = 4.0 - 0.8 * k - 0.05 * view
        error = 0.0 if k == 0 else 0.004 * k * (1 + view)
        pts.append((pack_indices(idx), error, power))
    times = [0.1, 0.08, 0.07, 0.06] if slow else [0.1, 0.03, 0.02, 0.01] if timed else None
    return Frontier.from_points([p[0] for p in pts], [p[1] for p in pts], [p[2] for p in pts], times,
                                fps=24.0 if times else None)


def synthetic_store(root_min: tuple[float, float, float] = (-10.0, -10.0, -10.0), size: float = 20.0,
                    timed: bool = False, slow: bool = False) -> ParetoStore:
    """One-leaf store (8 corners, 6 views each) with view-dependent frontiers (``timed``: with frame
    times, store format 4; ``slow``: with frame times none of which keeps up with its 24 fps)."""
    corners = np.array([[(k & 1), (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], dtype=np.int64)
    frontiers = [view_frontier(v, timed, slow) for v in range(6)]
    views = np.tile(np.arange(6, dtype=np.int64), (8, 1))
    return ParetoStore(parameters=PARAMETERS, root_min=np.asarray(root_min), root_size=size,
                       lattice_depth=0, children=np.array([-1]), corner_coords=corners, corner_views=views,
                       frontiers=frontiers,
                       vfov=0.69, aspect=16 / 9, profile="mobile", fps=24.0)


def stage_extension(tmp: Path) -> Path:
    """Stage the extension under `tmp` (the add-on folder only: this environment has the project's
    packages); returns the repo folder."""
    build_extension.stage(tmp)
    return tmp


def start_gui_job(bpy: Any) -> tuple[Any, Any]:
    """What the Optimize button's invoke() does, without a window: prepare on the main thread, a worker
    thread follows the job; returns (ops_optimize module, the active job). `ops._poll_queue()` is the
    timer's step."""
    import importlib
    import threading

    ops = importlib.import_module(f"{EXT_MODULE}.ops_optimize")
    client = importlib.import_module(f"{EXT_MODULE}.service_process").client_for(bpy.context)
    job = ops._ActiveJob(ops.prepare(bpy.context.scene), threading.Thread())
    job.thread = threading.Thread(target=ops._worker, args=(job, client), daemon=True)
    ops._active = job
    job.thread.start()
    return ops, job


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


@contextlib.contextmanager
def dev_extension(bpy: Any, tmp: Path) -> Iterator[Any]:
    """The add-on staged under `tmp` and enabled as a dev extension, disabled again on exit (the body of
    a module-scoped fixture)."""
    mod = enable_dev(bpy, stage_extension(tmp))
    try:
        yield mod
    finally:
        disable_dev()


def disable_dev() -> None:
    import addon_utils

    addon_utils.disable(EXT_MODULE, default_set=True, handle_error=_raise)


def _raise(exc: BaseException) -> None:
    raise exc


def alive(pid: int) -> bool:
    """A live process (zombies, whose parent has not reaped them yet, count as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def descendants(pid: int) -> list[int]:
    """Live processes below `pid` (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            if alive(c):
                out.append(c)
                todo.append(c)
    return out


def wait_gone(pids: list[int], timeout_s: float = 15.0) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and any(alive(p) for p in pids):
        time.sleep(0.1)
    return [p for p in pids if alive(p)]


def kill_and_check_nothing_left(parent: subprocess.Popen, below: list[int]) -> None:
    """SIGKILL the parent of a running local job (no clean-up code of ours runs) and check that the job
    process and its workers, `below` it, end too."""
    assert len(below) >= 3  # the job process and its two evaluation workers (+ resource tracker)
    parent.send_signal(signal.SIGKILL)
    parent.wait(timeout=10)
    assert wait_gone(below) == []


def cancel_gui_job(bpy: Any, ops: Any, job: Any) -> Any:
    """What the Cancel button does to a job :func:`start_gui_job` started, then the timer's last step;
    returns the window manager's runtime state (job status line)."""
    job.cancel.set()
    job.thread.join(120)
    assert not job.thread.is_alive()
    assert ops._poll_queue() is None
    return bpy.context.window_manager.render_budget_runtime


def store_json(store: ParetoStore) -> str:
    text = store.to_json()
    json.loads(text)
    return text
