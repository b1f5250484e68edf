"""Local work with the bundled core, no server: scenes are analysed in this process, and each optimisation
job runs in a child process (`python -m service.local_job`) started with this interpreter (Blender's own
Python inside Blender, the bpy module's interpreter in tests).

`LocalClient` answers what `job_runner.run_job`, the operators and path evaluation ask a `ServiceClient`
(`health`, `upload_scene`, `scene`, `submit_job`, `job`, `cancel_job`, `store_text`, `evaluate`,
`render`), with the same dictionaries the REST service returns, so local and remote work follow one code
path. Evaluations and renders run in this process (the native core releases the GIL: a thread pool of
evaluations uses every core).

A job process never outlives its job or this process: it watches a pipe from us (end of file: it kills
itself and its workers), asks Linux for SIGKILL when its parent dies, leads its own process group (stopping
it stops its workers), and `close()` (add-on disabled, Blender exiting) stops whatever still runs.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections import OrderedDict
from pathlib import Path
from typing import IO, Any

import numpy as np

import service
from service.camera_path import CameraPath
from service.options import query_fields
from service.store import ParetoStore, camera

from . import preview
from .client import RenderedImage, ServiceError

# The native core (sim_core, and the service modules that import it) is imported inside the functions that
# need it, "lazy" below: it loads on first use, not when the add-on registers, so Blender starts without it
# and playback, the panel and a remote service work even where it cannot load (the error then says why).

TERMINAL = ("done", "failed", "cancelled")
SCENES_KEPT = 8
JOB_MODULE = "service.local_job"
#: a job's folder for its build's camera references (``--scratch``), removed once the job has ended
SCRATCH_DIR = "scratch"
#: job folders and kept scenes untouched this long go when a client starts: failed jobs' logs, stores never
#: collected (Blender quit first), scenes of earlier sessions. Far beyond any local job's length (a running
#: job of another Blender sharing the folder writes its log and references), short enough to read a log.
STALE_AFTER_S = 7 * 24 * 3600.0


def _newest_mtime(path: Path) -> float:
    """The latest change to a file, or to a folder or anything in it (0 if it vanished meanwhile)."""
    newest = 0.0
    for item in (path, *path.rglob("*")) if path.is_dir() else (path,):
        try:
            newest = max(newest, item.stat().st_mtime)
        except OSError:
            continue
    return newest


def prune_stale(data_dir: str | Path, max_age_s: float = STALE_AFTER_S,
                now: float | None = None) -> list[Path]:
    """Remove job folders and kept scenes (and half-written copies) no one has touched for `max_age_s`;
    returns what went. The folder may be shared by several Blenders, so age is the only safe sign."""
    data_dir = Path(data_dir)
    cutoff = (time.time() if now is None else now) - max_age_s
    removed: list[Path] = []
    for folder in (data_dir / "jobs", data_dir / "scenes"):
        if not folder.is_dir():
            continue
        for item in sorted(folder.iterdir()):
            if _newest_mtime(item) >= cutoff:
                continue
            if item.is_dir():
                shutil.rmtree(item, ignore_errors=True)
            else:
                item.unlink(missing_ok=True)
            removed.append(item)
    return removed


def module_paths() -> list[str]:
    """Folders that hold the bundled packages (the extension's site-packages inside Blender): the job
    process gets them first on its path, since it does not run Blender's start-up code."""
    import sim_core  # lazy: the native core (above)

    out: list[str] = []
    for mod in (service, sim_core):
        folder = str(Path(mod.__file__).resolve().parent.parent)
        if folder not in out:
            out.append(folder)
    return out


def job_command(python: str | Path, args: list[str]) -> list[str]:
    """`python -I` (no user site, no PYTHON* variables: the user's other Pythons cannot leak in) running
    the job module with the bundled packages first on the path."""
    boot = (f"import sys, runpy; sys.path[:0] = {module_paths()!r}; "
            f"runpy.run_module({JOB_MODULE!r}, run_name='__main__', alter_sys=True)")
    return [str(python), "-I", "-c", boot, *args]


class LocalJobProcess:
    """One running job: the child process, a reader thread turning its JSON lines into REST-shaped state."""

    def __init__(self, job_id: str, command: list[str], work_dir: Path) -> None:
        self.id = job_id
        self.work_dir = work_dir
        self.store_path = work_dir / "store.json"
        self.log_path = work_dir / "job.log"
        self.scratch_dir = work_dir / SCRATCH_DIR
        self._stopped = False
        self._lock = threading.Lock()
        self._state: dict[str, Any] = {"id": job_id, "state": "queued", "progress": None, "error": None,
                                       "store_id": None}
        log = self.log_path.open("ab")
        try:
            posix = os.name == "posix"
            self.process = subprocess.Popen(
                command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, cwd=str(work_dir),
                start_new_session=posix,
                creationflags=0 if posix else subprocess.CREATE_NEW_PROCESS_GROUP)  # type: ignore[attr-defined]
        except OSError as err:
            raise RuntimeError(f"could not start a local job with the Python at {command[0]} ({err}); run "
                               "jobs on a remote service instead (add-on preferences)") from err
        finally:
            log.close()
        self._reader = threading.Thread(target=self._read, args=(self.process.stdout,),
                                        name=f"render-budget-job-{job_id[:8]}", daemon=True)
        self._reader.start()

    @property
    def pid(self) -> int:
        return self.process.pid

    def _set(self, **fields: Any) -> None:
        with self._lock:
            self._state.update(fields)

    def _read(self, stream: IO[bytes]) -> None:
        for raw in stream:
            try:
                msg = json.loads(raw.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError):
                continue  # not ours (a library printing to stdout); the log has stderr
            event = msg.get("event")
            if event == "started":
                self._set(state="running")
            elif event == "progress":
                self._set(state="running", progress=msg.get("progress"))
            elif event == "done":
                self._set(state="done", store_id=str(msg["store_id"]))
            elif event == "cancelled":
                self._set(state="cancelled")
            elif event == "failed":
                self._set(state="failed", error=str(msg.get("error") or "no message"))
        code = self.process.wait()
        # what a killed job could not remove (its camera references: MBs each at 1280x720)
        shutil.rmtree(self.scratch_dir, ignore_errors=True)
        with self._lock:
            if self._state["state"] not in TERMINAL and self._stopped:  # ended by stop(), not by itself
                self._state["state"] = "cancelled"
            if self._state["state"] not in TERMINAL:
                self._state.update(state="failed", error=f"the local job process exited with status {code}"
                                   f" before finishing; log: {self.log_path}\n{self.log_tail()}")
            cancelled = self._state["state"] == "cancelled"
        self._close_stdin()
        if cancelled:  # nothing in it is wanted any more (a failed job keeps its log, which its error names)
            shutil.rmtree(self.work_dir, ignore_errors=True)

    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            return dict(self._state)

    def running(self) -> bool:
        return self.process.poll() is None

    def cancel(self) -> None:
        """Ask the job to stop at its next evaluation batch (what it evaluated stays in the cache)."""
        try:
            if self.process.stdin is not None and not self.process.stdin.closed:
                self.process.stdin.write(b"cancel\n")
                self.process.stdin.flush()
        except (OSError, ValueError):
            pass

    def _close_stdin(self) -> None:
        try:
            if self.process.stdin is not None:
                self.process.stdin.close()
        except OSError:
            pass

    def stop(self, timeout_s: float = 5.0) -> None:
        """End the job now: closing its lifeline makes it kill itself and its workers; if it does not,
        its whole process group is killed (only while it runs: a reaped group id could be reused)."""
        if self.running():
            self._stopped = True
            self._close_stdin()
            try:
                self.process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                if os.name == "posix":
                    os.killpg(self.process.pid, signal.SIGKILL)
                else:
                    self.process.kill()
                self.process.wait(timeout=timeout_s)
        self._reader.join(timeout=timeout_s)
        with self._lock:
            if self._state["state"] not in TERMINAL:
                self._state["state"] = "cancelled"

    def log_tail(self, lines: int = 12) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


class LocalClient:
    """Jobs and scene analysis on this machine with the bundled core; files under `data_dir`."""

    def __init__(self, data_dir: str | Path, *, workers: int = 1, python: str | Path | None = None) -> None:
        if int(workers) < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.data_dir = Path(data_dir)
        self.workers = int(workers)
        self.python = str(python or sys.executable)
        self.base_url = "local"
        self.timeout_s = 3600.0
        self._jobs: dict[str, LocalJobProcess] = {}
        self._scenes: OrderedDict[str, dict[str, Any]] = OrderedDict()
        self._loaded: OrderedDict[str, Any] = OrderedDict()  # scene id -> sim_core.Scene (evaluate, render)
        self._lock = threading.Lock()
        prune_stale(self.data_dir)

    # -- what ServiceClient offers ---------------------------------------------------------------------
    def health(self, timeout_s: float | None = None) -> dict[str, Any]:
        import sim_core  # lazy: the native core (above)

        return {"status": "ok", "mode": "local", "version": getattr(sim_core, "__version__", "?"),
                "profiles": list(sim_core.list_profiles()), "workers": self.workers, "python": self.python}

    def upload_scene(self, scene_path: str | Path) -> dict[str, Any]:
        """Analyse a render-budget scene file (what the add-on sends) or a .glb the way POST /scenes does
        (the real loader, statistics with the translation notes, parameters the simulator reports inert)
        and keep a copy for jobs; answers the same fields."""
        from sim_core.loaders.scene_file import is_scene_file  # lazy: the native core (above)

        data = Path(scene_path).read_bytes()
        if data[:4] != b"glTF" and not is_scene_file(data[:64]):
            raise ValueError(f"{scene_path} is neither a render-budget scene file nor a binary glTF (.glb)")
        scene_id = hashlib.sha256(data).hexdigest()
        folder = self.data_dir / "scenes"
        kept = self._scene_file(scene_id, glb=data[:4] == b"glTF")
        present = kept.is_file()  # (another Blender's prune_stale may have removed it)
        if present:
            os.utime(kept)  # used again: not stale (prune_stale)
        with self._lock:
            known = self._scenes.get(scene_id)
            if known is not None and present:
                self._scenes.move_to_end(scene_id)
                return dict(known)
        folder.mkdir(parents=True, exist_ok=True)
        if not present:
            tmp = kept.with_suffix(".tmp")
            tmp.write_bytes(data)
            tmp.replace(kept)
        loaded, info = analyse_scene(kept)
        info.update(id=scene_id, size=len(data))
        with self._lock:
            self._scenes[scene_id] = info
            self._remember(scene_id, loaded)
            while len(self._scenes) > SCENES_KEPT:
                old, _ = self._scenes.popitem(last=False)
                self._loaded.pop(old, None)
                for stale in folder.glob(f"{old}.*"):
                    stale.unlink(missing_ok=True)
        return dict(info)

    def _scene_file(self, scene_id: str, glb: bool | None = None) -> Path:
        """Where a scene is kept: `<id>.glb` or `<id>.rbscene` (None: whichever exists)."""
        from sim_core.loaders.scene_file import SUFFIX  # lazy: the native core (above)

        folder = self.data_dir / "scenes"
        if glb is None:
            found = [p for p in (folder / f"{scene_id}.glb", folder / f"{scene_id}{SUFFIX}") if p.is_file()]
            return found[0] if found else folder / f"{scene_id}{SUFFIX}"
        return folder / (f"{scene_id}.glb" if glb else f"{scene_id}{SUFFIX}")

    def _remember(self, scene_id: str, scene: Any) -> None:
        """Keep the two most recent loaded scenes (a BVH is the expensive part; memory is the limit)."""
        self._loaded[scene_id] = scene
        self._loaded.move_to_end(scene_id)
        while len(self._loaded) > 2:
            self._loaded.popitem(last=False)

    def _scene(self, scene_id: str) -> Any:
        from service.evaluation import read_scene  # lazy: loads the native core (above)

        with self._lock:
            scene = self._loaded.get(scene_id)
            known = scene_id in self._scenes
        if scene is None:
            path = self._scene_file(scene_id)
            if not known or not path.is_file():
                raise ServiceError(404, f"scene {scene_id!r} not found: upload it first")
            scene = read_scene(path)
            with self._lock:
                self._remember(scene_id, scene)
        return scene

    def evaluate(self, payload: dict[str, Any], timeout_s: float | None = None) -> dict[str, Any]:
        """What POST /evaluate answers: error against the maximum-quality render of the same camera
        and power of `settings` (`{parameter: value}`), here; with `power_resolution` [w, h], power and
        frame time for that many pixels (static plus pixel-scaled dynamic power, as a store predicts it),
        scaled here once as the service does."""
        from service.evaluation import CameraSpec, evaluate  # lazy: loads the native core (above)

        cam = payload["camera"]
        m = _camera_matrix(cam["matrix_world"])
        spec = CameraSpec.from_matrix(m, cam["vfov"], cam["width"], cam["height"])
        space, indices = preview.settings_indices(payload.get("settings"))
        ev = evaluate(self._scene(str(payload["scene_id"])), spec, indices, space,
                      profile=str(payload.get("profile", "mobile")), fps=float(payload.get("fps", 30.0)),
                      target_pixels=_pixel_count(payload.get("power_resolution")))
        return {"error": float(ev.error), "power_w": float(ev.power_w),
                "frame_time_s": float(ev.frame_time_s), "breakdown": dict(ev.breakdown)}

    def verify_text(self, store_text: str, payload: dict[str, Any]) -> dict[str, Any]:
        """What POST /stores/{id}/verify answers, here, for the store given as its JSON text (a local
        job's store lives in the .blend, not in a service) and ``payload["scene_id"]``'s scene."""
        from service.verify import verify_store  # lazy: loads the native core (above)

        report = verify_store(self._scene(str(payload["scene_id"])), ParetoStore.from_json(store_text),
                              CameraPath.from_dict(payload["camera_path"]),
                              error_budget=payload.get("error_budget"),
                              power_budget=payload.get("power_budget_w"),
                              frames=int(payload.get("frames", 8)), resolution=payload.get("resolution"),
                              **query_fields(payload))
        return report.to_dict()

    def render(self, payload: dict[str, Any], timeout_s: float | None = None) -> RenderedImage:
        """What POST /render answers: the frame as PNG or EXR with its counters and energy report, here."""
        cam = payload["camera"]
        profile, fps = str(payload.get("profile", "mobile")), float(payload.get("fps", 30.0))
        result = preview.render(self._scene(str(payload["scene_id"])), _camera_matrix(cam["matrix_world"]),
                                cam["vfov"], int(cam["width"]), int(cam["height"]),
                                settings=payload.get("settings"), profile=profile, fps=fps)
        fmt = str(payload.get("format", "png")).lower()
        data = preview.encode(np.asarray(result.image), fmt)
        return RenderedImage(data, "image/x-exr" if fmt == "exr" else "image/png",
                             {"energy": result.energy, "counters": result.counters,
                              "render_time_s": result.render_s})

    def scene(self, scene_id: str) -> dict[str, Any]:
        with self._lock:
            info = self._scenes.get(scene_id)
        if info is None:
            raise ServiceError(404, f"scene {scene_id!r} not found")
        return dict(info)

    def submit_job(self, payload: dict[str, Any]) -> dict[str, Any]:
        scene_id = str(payload.get("scene_id", ""))
        scene_file = self._scene_file(scene_id)
        if scene_id not in self._scenes or not scene_file.is_file():
            raise ServiceError(404, f"scene {scene_id!r} not found: upload it first")
        job_id = uuid.uuid4().hex
        work = self.data_dir / "jobs" / job_id
        work.mkdir(parents=True)
        (work / "request.json").write_text(json.dumps(payload, allow_nan=False), encoding="utf-8")
        (self.data_dir / "cache").mkdir(parents=True, exist_ok=True)
        args = ["--request", str(work / "request.json"), "--scene", str(scene_file),
                "--store", str(work / "store.json"), "--scratch", str(work / SCRATCH_DIR),
                "--cache", str(self.data_dir / "cache" / "eval_cache.sqlite3"),
                "--workers", str(self.workers), "--parent-pid", str(os.getpid())]
        job = LocalJobProcess(job_id, job_command(self.python, args), work)
        with self._lock:
            self._jobs[job_id] = job
        return job.snapshot()

    def job(self, job_id: str) -> dict[str, Any]:
        return self._job(job_id).snapshot()

    def cancel_job(self, job_id: str) -> dict[str, Any]:
        job = self._job(job_id)
        state = job.snapshot()
        if state["state"] in TERMINAL:
            raise ServiceError(409, f"job {job_id} already {state['state']}")
        job.cancel()
        return job.snapshot()

    def store_text(self, store_id: str) -> str:
        with self._lock:
            jobs = list(self._jobs.values())
        for job in jobs:
            snap = job.snapshot()
            if snap["state"] == "done" and snap["store_id"] == store_id:
                text = job.store_path.read_text(encoding="utf-8")
                json.loads(text)
                self._forget(job)
                return text
        raise ServiceError(404, f"store {store_id!r} not found")

    # -- local only ------------------------------------------------------------------------------------
    def _job(self, job_id: str) -> LocalJobProcess:
        with self._lock:
            job = self._jobs.get(job_id)
        if job is None:
            raise ServiceError(404, f"job {job_id!r} not found")
        return job

    def _forget(self, job: LocalJobProcess) -> None:
        """The store has been handed over: the job's folder is no longer needed."""
        job.stop()
        with self._lock:
            self._jobs.pop(job.id, None)
        shutil.rmtree(job.work_dir, ignore_errors=True)

    def job_pids(self) -> list[int]:
        """Process ids of jobs still running (for status displays and tests)."""
        with self._lock:
            return [j.pid for j in self._jobs.values() if j.running()]

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop every job still running (the add-on is disabled or Blender exits)."""
        with self._lock:
            jobs = list(self._jobs.values())
        for job in jobs:
            job.stop(timeout_s)

    def wait_idle(self, timeout_s: float = 30.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while self.job_pids() and time.monotonic() < deadline:
            time.sleep(0.05)
        return not self.job_pids()


def _pixel_count(power_resolution: Any) -> int | None:
    """The pixels of POST /evaluate's `power_resolution` ([width, height], each 1..16384), None if absent."""
    if power_resolution is None:
        return None
    try:
        w, h = power_resolution
        w, h = camera.check_resolution(w, h)
    except (TypeError, ValueError) as err:
        raise ValueError(f"power_resolution must be [width, height]: {err}") from None
    return w * h


def _camera_matrix(matrix: Any) -> np.ndarray:
    m = np.array(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError("camera matrix_world must be a finite 4x4 matrix")
    m[3] = (0.0, 0.0, 0.0, 1.0)
    return m


def analyse_scene(path: str | Path) -> tuple[Any, dict[str, Any]]:
    """Load a scene file (render-budget scene file or .glb) with the real loader; the scene, its
    statistics (with a scene file's translation notes) and the parameters it cannot exercise."""
    from sim_core.loaders.scene_file import is_scene_file, read_scene_file  # lazy: the native core (above)

    import sim_core  # lazy: the native core (above)
    from service.params import default_space  # lazy: loads the native core (above)

    notes: list[Any] = []
    scene_file = is_scene_file(Path(path))
    try:
        if scene_file:
            content = read_scene_file(path)
            notes = content.notes
            scene = sim_core.Scene.from_scene_data(content.data)
        else:
            scene = sim_core.Scene.from_gltf(str(path))
    except (ValueError, FileNotFoundError) as exc:
        raise ValueError(f"the simulator cannot load this scene: {exc}") from exc
    stats = {k: (v if isinstance(v, int | float | str | bool | list | dict) else str(v))
             for k, v in dict(scene.stats).items()}
    stats["format"] = "scene" if scene_file else "glb"
    if notes:
        stats["notes"] = notes
    inert = {str(k): str(v) for k, v in sim_core.inert_parameters(scene, default_space().as_render_space())
             .items()}
    return scene, {"content_hash": str(scene.content_hash), "stats": stats, "inert_parameters": inert,
                   "cameras": len(scene.cameras)}
