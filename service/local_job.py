"""One optimisation job in a child process of Blender: the add-on's local path, with no server.

    python -m service.local_job --request job.json --scene scene.glb --store store.json \\
        --cache eval_cache.sqlite3 [--workers N] [--parent-pid PID] [--scratch DIR]

The request is the body of ``POST /jobs`` (``scene_id`` is ignored: the scene is the file given), so a
local job and a service job run the same optimiser inputs through :func:`service.jobs.run_optimisation`.
The evaluation cache is SQLite, so a cancelled or killed job resumes without re-rendering.

Protocol with the parent, which must never be outlived:

- stdout carries JSON lines: ``{"event": "started", "pid"}``, ``{"event": "progress", "progress": {...}}``
  (the fields of ``service.optimize.Progress``, as the REST job reports them), then one of
  ``{"event": "done", "store": path, "store_id": sha256}``, ``{"event": "cancelled"}``,
  ``{"event": "failed", "error": message}``;
- stdin is the lifeline: a line ``cancel`` stops the job at the next evaluation batch; end of file means
  the parent is gone (closed the pipe, exited or was killed): the job and its worker processes end at
  once: it kills its own process group (its evaluation workers and multiprocessing's helper go with it).
  The kernel closes the pipe however the parent ended, SIGKILL included. (A kernel death signal on the
  job itself would kill it before it could take its workers along);
- the exit status is 0 (done), 1 (failed), 3 (cancelled).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from service.eval_cache import EvalCache
from service.evaluation import load_scene
from service.executors import make_executor
from service.jobs import progress_dict, run_optimisation, validate_job_spec
from service.optimize import Cancelled

EXIT_DONE, EXIT_FAILED, EXIT_CANCELLED = 0, 1, 3
PROGRESS_INTERVAL_S = 0.2

_emit_lock = threading.Lock()


def emit(event: str, **fields: Any) -> None:
    """One JSON line on stdout (the parent's reader thread parses them)."""
    line = json.dumps({"event": event, **fields}, allow_nan=False, default=str)
    with _emit_lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def kill_everything() -> None:
    """End this job and its worker processes now (the parent is gone or asked for it)."""
    try:
        if hasattr(os, "killpg") and os.getpgrp() == os.getpid():  # started as a process-group leader
            os.killpg(os.getpid(), signal.SIGKILL)
    except OSError:
        pass
    for child in multiprocessing.active_children():
        child.kill()
    os._exit(EXIT_CANCELLED)


def watch_lifeline(cancel: threading.Event, stream: Any = None) -> threading.Thread:
    """Read the parent's pipe: ``cancel`` sets the flag; end of file ends everything at once."""
    source = stream if stream is not None else sys.stdin.buffer

    def run() -> None:
        try:
            for raw in source:
                if raw.strip().lower() == b"cancel":
                    cancel.set()
        except (OSError, ValueError):
            pass
        kill_everything()

    t = threading.Thread(target=run, name="render-budget-lifeline", daemon=True)
    t.start()
    return t


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m service.local_job", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--request", type=Path, required=True, help="job request JSON (the POST /jobs body)")
    ap.add_argument("--scene", type=Path, required=True, help="the scene (.glb)")
    ap.add_argument("--store", type=Path, required=True, help="where to write the Pareto store (JSON)")
    ap.add_argument("--cache", type=Path, required=True, help="SQLite evaluation cache")
    ap.add_argument("--workers", type=int, default=1, help="evaluation processes (1: in this process)")
    ap.add_argument("--parent-pid", type=int, default=None,
                    help="exit at once if this is no longer the parent (it died before we started)")
    ap.add_argument("--scratch", type=Path, default=None,
                    help="folder for the build's camera references while it runs (MBs each at 1280x720; "
                         "default: the system's temporary folder). A killed job cannot remove them, so "
                         "the parent gives a folder of its own and removes it when the job has ended")
    return ap


def run(args: argparse.Namespace) -> int:
    cancel = threading.Event()
    watch_lifeline(cancel)
    emit("started", pid=os.getpid())
    t0 = time.monotonic()
    try:
        spec = json.loads(args.request.read_text(encoding="utf-8"))
        if not isinstance(spec, dict):
            raise ValueError("the job request must be a JSON object")
        validate_job_spec(spec)
        if args.workers < 1:
            raise ValueError(f"workers must be >= 1, got {args.workers}")
        handle = load_scene(args.scene)
        if args.scratch is not None:
            args.scratch.mkdir(parents=True, exist_ok=True)
    except Exception as exc:  # bad input: say what, exit
        emit("failed", error=f"{type(exc).__name__}: {exc}")
        return EXIT_FAILED
    last = [0.0]

    def on_progress(progress: Any) -> None:
        now = time.monotonic()
        if now - last[0] >= PROGRESS_INTERVAL_S or getattr(progress, "phase", "") == "done":
            last[0] = now
            emit("progress", progress=progress_dict(progress, elapsed_s=now - t0))

    # Worker processes of the pool die with this one (service.executors); each renders with its share of
    # the cores.
    executor = make_executor(workers=args.workers)
    threads = max(1, (os.cpu_count() or 1) // args.workers) if args.workers > 1 else None
    try:
        with EvalCache(args.cache) as cache:
            store = run_optimisation(spec, scene=handle, cache=cache, executor=executor, progress=on_progress,
                                     should_cancel=cancel.is_set, threads=threads, scratch_dir=args.scratch)
    except Cancelled:
        emit("cancelled")
        return EXIT_CANCELLED
    except Exception as exc:  # the parent shows this message to the user
        emit("failed", error=f"{type(exc).__name__}: {exc}")
        return EXIT_FAILED
    finally:
        executor.close()
    if cancel.is_set():
        emit("cancelled")
        return EXIT_CANCELLED
    text = store.to_json()
    args.store.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.store.with_suffix(".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(args.store)
    emit("done", store=str(args.store), store_id=hashlib.sha256(text.encode("utf-8")).hexdigest(),
         elapsed_s=round(time.monotonic() - t0, 3))
    return EXIT_DONE


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.parent_pid is not None and os.getppid() != args.parent_pid:
        return EXIT_CANCELLED  # the parent died before we started
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
