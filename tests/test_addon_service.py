"""The add-on against a live local service (`render-budget serve` on a free 127.0.0.1 port, started by the
add-on's own LocalService helper): optimize end to end, the store in the .blend through save/reload,
playback along the path matching `render-budget query` and the service's query route, the GUI worker
thread path and cancel, previews, and headless batch runs writing a report."""

from __future__ import annotations

import csv
import importlib
import json
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from addon.core.client import ServiceClient
from addon.core.local_service import LocalService, free_port
from service.store import ParetoStore
from tests import orbit_scene
from tests.addon_support import (
    EXT_MODULE,
    REPO_ROOT,
    cancel_gui_job,
    disable_dev,
    enable_dev,
    stage_extension,
    start_gui_job,
)

pytestmark = [pytest.mark.blender, pytest.mark.service, pytest.mark.slow]
bpy = pytest.importorskip("bpy")

FRAMES = 16
RES = (96, 54)  # scene render size: the path's aspect, so the add-on and the CLI see the same frustum


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory):
    svc = LocalService(sys.executable, free_port(), tmp_path_factory.mktemp("service-data"))
    svc.start(ready_timeout_s=120)
    yield svc
    svc.stop()


@pytest.fixture(scope="module")
def ext(tmp_path_factory: pytest.TempPathFactory, service):
    mod = enable_dev(bpy, stage_extension(tmp_path_factory.mktemp("ext")))
    prefs = importlib.import_module(f"{EXT_MODULE}.preferences").get()
    prefs.service_mode, prefs.url, prefs.timeout_s = "REMOTE", service.url, 120
    yield mod
    disable_dev()


def m(name: str):
    return importlib.import_module(f"{EXT_MODULE}.{name}")


def build_scene() -> bpy.types.Scene:
    """The orbiting box scene with a search space of 3 parameters and small optimiser options."""
    sc = orbit_scene.build(bpy, FRAMES, RES)
    orbit_scene.small_job(sc.render_budget)
    return sc


@pytest.fixture(scope="module")
def optimized(ext, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Optimize once (synchronous operator path) and save the .blend."""
    sc = build_scene()
    assert bpy.ops.render_budget.optimize() == {"FINISHED"}
    assert sc.render_budget.store_text is not None
    blend = tmp_path_factory.mktemp("blend") / "optimized.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    return blend


def _varied_budget(store, path) -> float:
    """The error budget (among midpoints of the stored frontier errors) under which the store's own
    choice varies most along the recorded path: the test then checks the add-on follows those changes."""
    errs = np.unique(np.concatenate([f.error for f in store.frontiers]))
    candidates = [float(v) for v in (errs[:-1] + errs[1:]) / 2] or [0.01]

    def variety(budget: float) -> int:
        return len({store.lookup(f.position, matrix=f.matrix_world, fov=f.vfov, aspect=f.aspect,
                                 error_budget=budget).indices for f in path.frames})

    return max(candidates, key=variety)


def test_optimize_end_to_end_store_in_blend_and_playback_matches_query(optimized, service, tmp_path) -> None:
    from service.store import ParetoStore

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.wm.open_mainfile(filepath=str(optimized))  # the store survived save and reload
    sc = bpy.context.scene
    props = sc.render_budget
    text = props.store_text.as_string()
    store = ParetoStore.from_json(text)
    assert props.store_id and props.job_id and "views" in props.summary
    assert json.loads(text) == json.loads(ServiceClient(service.url).store_text(props.store_id))
    # the job optimised the depsgraph translation (a scene file), not a glTF export
    assert ServiceClient(service.url).scene(props.scene_id)["stats"]["format"] == "scene"
    assert [p.name for p in store.parameters if len(p.values) > 1]  # something was searched
    from service.camera_path import CameraPath

    budget = _varied_budget(store, CameraPath.from_json(props.path_text.as_string()))
    props.budget_mode, props.error_budget = "ERROR", budget
    seen = []
    for f in range(sc.frame_start, sc.frame_end + 1):
        sc.frame_set(f)
        assert props.playback_status in ("on target", "blending"), props.playback_status
        seen.append((props.active_indices, props.target_indices, props.predicted_power, props.predicted_error,
                     np.array(sc.camera.matrix_world), sc.camera.data.angle_y))
    targets = [s[1] for s in seen]
    assert len(set(targets)) >= 2, "settings should change along the orbit"
    assert any(a != t for a, t, *_ in seen), "the temporal filter blends at target changes"
    # the filter (Eq. 8's pace along the frontier) on scene time: the pure driver's answers on the same poses
    from addon.core.playback_logic import PlaybackDriver

    drv = PlaybackDriver(store, props.filter_period)
    vf = m("camera_path").camera_vfov(sc.camera, sc)
    for i, (active, *_rest, mat, _) in enumerate(seen):
        fr = drv.step(mat, vf, RES[0] / RES[1], i / 24, "ERROR", budget)
        assert " ".join(map(str, fr.active_indices)) == active
    # the same poses through `render-budget query` (CLI) and POST /stores/{id}/query
    store_file = tmp_path / "store.json"
    store_file.write_text(text)
    client = ServiceClient(service.url)
    cli = Path(sys.executable).parent / "render-budget"
    vfov = m("camera_path").camera_vfov(sc.camera, sc)
    for active, target, power, error, mat, _ in seen[:: max(1, FRAMES // 4)]:
        pos, direction = mat[:3, 3], -mat[:3, 2]
        q = client.query(props.store_id, {"position": pos.tolist(), "matrix": mat.tolist(), "fov": vfov,
                                          "error_budget": budget})
        assert " ".join(map(str, q["indices"])) == target
        if active == target:  # playback shows the predictions of the settings it shows
            assert q["power_w"] == pytest.approx(power, rel=1e-6)
            assert q["error"] == pytest.approx(error, abs=1e-6)
        def nums(a: np.ndarray) -> list[str]:
            # positional notation: argparse would take "-1e-08" for an option
            return [np.format_float_positional(float(v), trim="-") for v in np.asarray(a).reshape(-1)]

        for orient in (["--matrix", *nums(mat)], ["--direction", *nums(direction)]):
            out = subprocess.run([str(cli), "query", str(store_file), "--json", "--position", *nums(pos),
                                  *orient, "--fov", repr(math.degrees(vfov)), "--error-budget", repr(budget)],
                                 capture_output=True, text=True, timeout=60, check=False)
            assert out.returncode == 0, out.stderr
            doc = json.loads(out.stdout)
            assert " ".join(map(str, doc["indices"])) == target, (orient[0], doc)
            assert doc["power_w"] == pytest.approx(q["power_w"], rel=1e-6)


def test_gui_path_worker_thread_and_queue(ext) -> None:
    """invoke()'s machinery without a window: the worker thread does HTTP, the timer callback applies."""
    sc = build_scene()
    ops, job = start_gui_job(bpy)
    job.thread.join(600)
    assert not job.thread.is_alive()
    assert ops._poll_queue() is None  # drained: job finished, timer would stop
    rt = bpy.context.window_manager.render_budget_runtime
    assert rt.job_status.startswith("done"), rt.job_status
    assert rt.job_progress == 1.0 and sc.render_budget.store_text is not None


def test_cancel_from_the_gui_path(ext, service) -> None:
    sc = build_scene()
    sc.render_budget.seed = 12345  # a job the cache has not seen
    # and a search no machine finishes before the first poll's Cancel (not the small job's exhaustive
    # enumeration)
    sc.render_budget.max_depth, sc.render_budget.population, sc.render_budget.generations = 2, 64, 500
    sc.render_budget.exhaustive_limit = 0
    ops, job = start_gui_job(bpy)
    deadline = time.monotonic() + 60
    while job.messages.qsize() < 2 and time.monotonic() < deadline:  # uploaded, submitted, first poll
        time.sleep(0.02)
    rt = cancel_gui_job(bpy, ops, job)
    assert "cancelled" in rt.job_status and sc.render_budget.store_text is None
    assert "service state: cancelled" in rt.job_status
    job_id = re.search(r"job (\S+) cancelled", rt.job_status).group(1)
    assert ServiceClient(service.url).job(job_id)["state"] == "cancelled"


@pytest.mark.parametrize("fmt", ["PNG", "EXR"])
def test_preview_renders_into_an_image(ext, fmt: str) -> None:
    sc = build_scene()
    sc.frame_set(3)
    assert bpy.ops.render_budget.preview(format=fmt, scale=0.5, use_active=False) == {"FINISHED"}
    img = bpy.data.images[m("ops_preview").IMAGE_NAME]
    assert tuple(img.size) == (48, 27) and img.packed_file is not None
    px = np.empty(48 * 27 * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    assert np.isfinite(px).all() and px.reshape(-1, 4)[:, :3].max() > 0.0  # not a black frame
    assert img.file_format == ("OPEN_EXR" if fmt == "EXR" else "PNG")


def _batch(args: list[str], tmp: Path) -> subprocess.CompletedProcess:
    """A batch run with its own temp dir, which it must leave without render-budget folders."""
    system_tmp = tmp / "system-tmp"
    system_tmp.mkdir(exist_ok=True)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp / "user"), TMPDIR=str(system_tmp))
    proc = subprocess.run([sys.executable, "-m", "addon.batch", *args], cwd=REPO_ROOT, capture_output=True,
                          text=True, env=env, timeout=900, check=False)
    assert list(system_tmp.glob("render-budget-*")) == [], proc.stdout + proc.stderr
    return proc


def test_batch_evaluate_and_playback_write_reports(optimized, service, tmp_path) -> None:
    out = tmp_path / "report"
    proc = _batch(["--blend", str(optimized), "--url", service.url, "evaluate", "--out", str(out),
                   "--frame-step", "4", "--budget-mode", "error", "--budget", "0.05", "--fps", "12",
                   "--priority", "budget", "--error-margin", "0.001", "--power-margin", "0.05"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "evaluate [" in proc.stdout and "Avg. Power (W)" in proc.stdout
    # the same report folder as `make demo` (one campaign module): both budget modes, summary, PNG + EXR
    for name in ("report.md", "per_frame.csv", "power_over_time.png", "error_over_time.png", "store.json",
                 "summary.json"):
        assert (out / name).is_file(), name
    with (out / "per_frame.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 * 6  # 4 frames x (4 presets + ours under the power and under the error budget)
    assert {r["mode"] for r in rows} == {"max", "max_mid", "mid_min", "min", "ours_power", "ours_error"}
    assert sorted({int(r["frame"]) for r in rows}) == [0, 4, 8, 12]  # path indices, as in the demo
    summary = json.loads((out / "summary.json").read_text())
    assert summary["error_budget"] == pytest.approx(0.05) and summary["frames_evaluated"] == 4
    assert summary["power_budget_w"] == pytest.approx(2.0)  # the scene's power budget (given)
    # the query options reached both budget modes' lookups, and every mode was measured at that rate
    assert summary["lookup"] == {"fps": 12.0, "fps_given": 12.0, "priority": "budget", "error_margin": 0.001,
                                 "power_margin": 0.05}
    assert summary["fps_target"] == 12.0 and all(0.0 < float(r["fps"]) <= 12.0 for r in rows)
    assert ("looked up for 12 fps (asked for), budget first, the error budget with a 0.001 margin, the power "
            "budget with a 5 % margin"
            in (out / "report.md").read_text())
    samples = sorted(p.name for p in (out / "frames").iterdir())
    assert samples[:2] == ["frame00000_max.exr", "frame00000_max.png"]
    assert {p.rsplit(".", 1)[1] for p in samples} == {"png", "exr"} and len(samples) == 3 * 4 * 2
    assert "Time per phase" in (out / "report.md").read_text()
    csv_out = tmp_path / "play.csv"
    proc = _batch(["--blend", str(optimized), "playback", "--out", str(csv_out)], tmp_path)
    assert proc.returncode == 0, proc.stderr
    played = list(csv.DictReader(csv_out.open(newline="")))
    assert len(played) == FRAMES
    assert all(float(r["predicted_fps"]) > 0.0 for r in played)  # a job's store knows frame times
    # the .blend's query options (not changed by evaluate, which does not save): its own rate, frame first
    assert {(r["priority"], r["meets_fps"] in ("0", "1")) for r in played} == {("frame_rate", True)}
    job_store = ParetoStore.from_json((out / "store.json").read_text())
    assert {float(r["fps_target"]) for r in played} == {job_store.fps}
    # every predicted figure names the display it holds for: the job priced at the scene's own size
    size = "{}x{}".format(*job_store.figures.resolution)
    assert job_store.figures.kind == "display" and {r["predicted_for"] for r in played} == {size}
    assert f"(for {size})" in proc.stdout
    proc = _batch(["--blend", str(optimized), "playback", "--out", str(csv_out), "--priority", "budget",
                   "--fps", "12"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    played = list(csv.DictReader(csv_out.open(newline="")))
    assert {(r["priority"], float(r["fps_target"])) for r in played} == {("budget", 12.0)}
    proc = _batch(["--blend", str(optimized), "playback", "--priority", "speed"], tmp_path)
    assert proc.returncode != 0 and "invalid choice: 'speed'" in proc.stderr


def test_batch_fails_loudly(optimized, tmp_path) -> None:
    dead = f"http://127.0.0.1:{free_port()}"
    proc = _batch(["--blend", str(optimized), "--url", dead, "evaluate", "--out", str(tmp_path / "r")],
                  tmp_path)
    assert proc.returncode == 1 and "no render-budget service" in proc.stderr
    proc = _batch(["--blend", str(tmp_path / "missing.blend"), "playback"], tmp_path)
    assert proc.returncode == 1 and "failed" in proc.stderr


def test_batch_optimize_searches_the_values_given_and_keeps_them_in_the_blend(optimized, service,
                                                                               tmp_path) -> None:
    """``optimize --space NAME=V1,...`` puts the values into the .blend's parameter list, the job
    searches them (the store says so) and the saved file lists them; a bad value changes nothing."""
    saved, store_out = tmp_path / "finer.blend", tmp_path / "store.json"
    proc = _batch(["--blend", str(optimized), "--url", service.url, "optimize", "--space",
                   "shadow_samples=0,1,2,4,16", "--save-as", str(saved), "--store-out", str(store_out)],
                  tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    store = ParetoStore.from_json(store_out.read_text())
    assert {p.name: p.values for p in store.parameters}["shadow_samples"] == (0, 1, 2, 4, 16)
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    assert bpy.context.scene.render_budget.parameters["shadow_samples"].values == "0, 1, 2, 4, 16"
    before = optimized.read_bytes()
    proc = _batch(["--blend", str(optimized), "--url", service.url, "optimize", "--space",
                   "shadow_samples=0,3"], tmp_path)
    assert proc.returncode == 1 and "'3' is not a value of 'shadow_samples'" in proc.stderr
    assert optimized.read_bytes() == before
