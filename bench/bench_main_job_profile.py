"""Where the main job's CPU goes (``make demo``): native renders by size and kind, repeated renders, and
what is not rendering, for the optimisation and for the evaluation campaign.

Runs, in this one process and with one tracer thread per render (so that each render's CPU time is the
thread's own), what ``make demo`` runs in the service:

1. the optimisation of the demo's job (``tools.demo.job_request``: the service defaults plus the demo's
   stated display size and points; or the options given), in-process;
2. the evaluation campaign over that store (``addon.core.campaign.measure``: the four presets, then both
   budget modes) against a real service app (uvicorn on 127.0.0.1 in a thread of this process, its own
   evaluation cache in a temporary folder), ``--concurrency`` requests in flight;
3. the verify step (``service.verify.verify_store``, what POST /stores/{id}/verify runs).

Every render is counted by (phase, size, sampling mode; reference or not), and a render of a (camera,
settings, size) already rendered in the same phase is counted as a repeat. Prints one table per phase
and the phases' CPU seconds (renders, the rest).

    .venv/bin/python bench/bench_main_job_profile.py                  # the demo's job (about 15 CPU-min)
    .venv/bin/python bench/bench_main_job_profile.py --population 4 --generations 2 --frames 6
"""

from __future__ import annotations

import collections
import json
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import sim_core  # noqa: E402
from addon.core import campaign  # noqa: E402
from addon.core.client import ServiceClient  # noqa: E402
from addon.core.local_service import free_port  # noqa: E402
from service.camera_path import CameraPath  # noqa: E402
from service.eval_cache import EvalCache  # noqa: E402
from service.evaluation import SceneHandle  # noqa: E402
from service.executors import InProcessExecutor  # noqa: E402
from service.jobs import build_space, spec_options  # noqa: E402
from service.optimize import OptimizeConfig, optimize_path  # noqa: E402
from service.verify import verify_store  # noqa: E402
from tools import demo  # noqa: E402


class RenderLog:
    """Wraps ``sim_core.render`` and ``render_window``: one tracer thread each, CPU time per kind."""

    def __init__(self) -> None:
        self.phase = "setup"
        self.rows: dict[tuple[str, str, str], list[float]] = collections.defaultdict(lambda: [0, 0.0, 0, 0.0])
        self.seen: set[tuple[Any, ...]] = set()
        self.lock = threading.Lock()
        self.real_render, self.real_window = sim_core.render, sim_core.render_window

    def install(self) -> None:
        sim_core.render, sim_core.render_window = self.render, self.window

    def _count(self, kind: str, camera: Any, settings: Any, key: tuple[Any, ...], cpu: float) -> None:
        row_key = (self.phase, f"{camera.width}x{camera.height}", kind)
        with self.lock:
            row = self.rows[row_key]
            row[0] += 1
            row[1] += cpu
            if key in self.seen:
                row[2] += 1
                row[3] += cpu
            self.seen.add(key)

    def render(self, scene: Any, camera: Any, settings: Any = None, threads: Any = None, *a: Any,
               **k: Any) -> Any:
        t = time.thread_time()
        r = self.real_render(scene, camera, settings, 1, *a, **k)
        kind = "tile 4" if settings.tile_size == 4 else settings.mode
        key = (self.phase, camera.frame().tobytes(), camera.vfov, camera.width, camera.height, repr(settings))
        self._count(kind, camera, settings, key, time.thread_time() - t)
        return r

    def window(self, scene: Any, camera: Any, settings: Any, window: Any, threads: Any = None, *a: Any,
               **k: Any) -> Any:
        t = time.thread_time()
        r = self.real_window(scene, camera, settings, window, *a, threads=1, **k)
        key = (self.phase, camera.frame().tobytes(), camera.vfov, repr(settings), tuple(window))
        self._count(f"window {settings.mode}", camera, settings, key, time.thread_time() - t)
        return r

    def table(self, phase: str, cpu_s: float) -> str:
        lines = [f"{phase}: {cpu_s:.1f} CPU-s", "",
                 "| size | sampling | renders | CPU-s | repeats | repeats' CPU-s |",
                 "|---|---|---|---|---|---|"]
        rendered = 0.0
        for (ph, size, kind), (n, cpu, rep, rep_cpu) in sorted(self.rows.items(), key=lambda kv: -kv[1][1]):
            if ph == phase:
                rendered += cpu
                lines.append(f"| {size} | {kind} | {n} | {cpu:.1f} | {rep} | {rep_cpu:.1f} |")
        lines.append(f"| | not rendering | | {cpu_s - rendered:.1f} | | |")
        return "\n".join(lines)


def serve(data_dir: Path) -> tuple[Any, threading.Thread, str]:
    """The service app in a thread of this process (so that its renders are counted here)."""
    import uvicorn

    from service.api import Settings, create_app

    port = free_port()
    server = uvicorn.Server(uvicorn.Config(create_app(Settings(data_dir=data_dir)), host="127.0.0.1",
                                           port=port, log_level="warning", access_log=False))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        if time.monotonic() > deadline:
            raise RuntimeError("the service did not start")
        time.sleep(0.05)
    return server, thread, f"http://127.0.0.1:{port}"


def main() -> None:
    ap = demo.parser()
    ap.description = __doc__
    args = ap.parse_args()
    scene_dir, _ = demo.build_scene(args.scene, skip=True)
    path_doc = json.loads((scene_dir / "path.json").read_text())
    path = CameraPath.from_dict(path_doc)
    request = demo.job_request(args)
    log = RenderLog()
    log.install()

    log.phase = "optimise"
    spec = {"options": request.options}
    config = OptimizeConfig(**spec_options(spec), profile=request.profile, fps=path.fps, threads=1)
    handle = SceneHandle(path=scene_dir / "scene.rbscene", self_contained=True)
    c0 = time.process_time()
    store = optimize_path(handle, path, build_space(spec), config, cache=EvalCache(None),
                          executor=InProcessExecutor())
    cpu = {"optimise": time.process_time() - c0}
    meta = store.meta
    print(f"store: {meta['evaluations']} renders asked for, {meta['display_cameras']} cameras priced at "
          f"{meta['figures_resolution']} ({meta['display_points']} points)", flush=True)

    with tempfile.TemporaryDirectory(prefix="bench-main-job-") as tmp:
        server, thread, url = serve(Path(tmp))
        try:
            client = ServiceClient(url, timeout_s=600.0)
            scene_id = client.upload_scene(scene_dir / "scene.rbscene")["id"]
            resolution = campaign.size_for_path(path, request.option("eval_height"),
                                                request.option("eval_width"))
            measured_at, power_at = campaign.measurement_sizes(store.to_json(), resolution, path)
            cs = campaign.CampaignSpec(scene_id=scene_id, resolution=measured_at, power_resolution=power_at,
                                       frame_step=campaign.frame_step(len(path), args.frames),
                                       error_budget=args.error_budget, concurrency=args.concurrency)
            log.phase = "evaluate"
            c0 = time.process_time()
            campaign.measure(client, store, path, cs)
            cpu["evaluate"] = time.process_time() - c0
            if args.verify_frames > 0:  # what POST /stores/{id}/verify runs, called here directly
                log.phase = "verify"
                c0 = time.process_time()
                verify_store(handle.get(), store, path, error_budget=args.error_budget,
                             frames=args.verify_frames, resolution=tuple(meta["figures_resolution"]))
                cpu["verify"] = time.process_time() - c0
        finally:
            server.should_exit = True
            thread.join(30)
    for phase in cpu:
        print()
        print(log.table(phase, cpu[phase]))


if __name__ == "__main__":
    main()
