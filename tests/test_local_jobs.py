"""The add-on's local path without Blender: LocalClient analyses scenes in-process and runs each job in a
`python -m service.local_job` child. The store equals the in-process optimiser's for the same request;
cancel stops the job and keeps its evaluations; the job and its workers die with their parent."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest

from addon.core.client import ServiceClient, ServiceError
from addon.core.job_runner import JobCancelled, JobFailed, JobRequest, run_job
from addon.core.local_jobs import STALE_AFTER_S, LocalClient, job_command, prune_stale
from tests.addon_support import descendants, kill_and_check_nothing_left
from tests.api_support import (
    box_scene_glb,
    camera_path,
    comparable,
    server_thread,
    teapot_scene_glb,
    tiny_job,
)


@pytest.fixture
def glb(tmp_path: Path) -> Path:
    path = tmp_path / "box.glb"
    path.write_bytes(box_scene_glb())
    return path


def test_upload_answers_what_the_service_answers(glb: Path, tmp_path: Path) -> None:
    client = LocalClient(tmp_path / "data")
    info = client.upload_scene(glb)
    assert info["stats"]["triangles"] == 14 and info["size"] == glb.stat().st_size
    assert "multirate" in info["inert_parameters"]  # nothing adaptive can differ in this scene
    assert client.scene(info["id"]) == info
    assert client.upload_scene(glb) == info  # same content: same id, no second analysis
    assert client.health()["mode"] == "local" and "mobile" in client.health()["profiles"]
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"not a glb")
    with pytest.raises(ValueError, match="neither a render-budget scene file nor a binary glTF"):
        client.upload_scene(bad)
    with pytest.raises(ServiceError, match="not found"):
        client.submit_job(tiny_job("0" * 64))


def test_a_client_removes_what_no_one_touched_for_a_week(glb: Path, tmp_path: Path) -> None:
    """Failed jobs' folders, stores Blender quit before collecting and scenes of earlier sessions go when a
    client starts; anything touched within the week stays (another Blender may be using it)."""
    data = tmp_path / "data"
    old = time.time() - STALE_AFTER_S - 3600
    recent = time.time() - STALE_AFTER_S + 3600

    def made(path: Path, when: float, text: str = "x") -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        os.utime(path, (when, when))
        os.utime(path.parent, (when, when))
        return path

    made(data / "jobs" / "failed" / "job.log", old)
    made(data / "jobs" / "uncollected" / "store.json", old)
    made(data / "jobs" / "busy" / "request.json", old)
    made(data / "jobs" / "busy" / "scratch" / "reference.exr", recent)  # still writing: stays
    made(data / "scenes" / "gone.rbscene", old)
    made(data / "scenes" / "half.tmp", old)
    made(data / "scenes" / "fresh.rbscene", recent)
    client = LocalClient(data)
    assert sorted(p.name for p in (data / "jobs").iterdir()) == ["busy"]
    assert sorted(p.name for p in (data / "scenes").iterdir()) == ["fresh.rbscene"]
    # a scene uploaded again counts as used: its kept copy is not stale a week after the first upload
    info = client.upload_scene(glb)
    kept = data / "scenes" / f"{info['id']}.glb"
    os.utime(kept, (old, old))
    assert client.upload_scene(glb) == info and prune_stale(data) == [] and kept.is_file()
    kept.unlink()  # removed by another Blender's client: uploading again puts it back
    assert client.upload_scene(glb) == info and kept.is_file()
    assert prune_stale(data, now=time.time() + STALE_AFTER_S + 60) != []  # a week on, everything goes
    assert list((data / "scenes").iterdir()) == [] and list((data / "jobs").iterdir()) == []


@pytest.mark.service
def test_local_answers_equal_the_services(glb: Path, tmp_path: Path) -> None:
    """Scene analysis, /evaluate and /render: the local client and a real service answer the same."""
    from service.api import Settings

    local = LocalClient(tmp_path / "local")
    frame = camera_path(3)["frames"][1]
    with server_thread(Settings(data_dir=tmp_path / "service")) as url:
        remote = ServiceClient(url, timeout_s=120)
        a, b = local.upload_scene(glb), remote.upload_scene(glb)
        for key in ("id", "stats", "inert_parameters", "cameras"):
            assert a[key] == b[key], key
        camera = {"matrix_world": frame["matrix_world"], "vfov": frame["vfov"], "width": 32, "height": 24}
        for settings in ({}, {"sampling": "1spp", "shadow_samples": 1}):
            body = {"scene_id": a["id"], "camera": camera, "settings": settings, "profile": "mobile",
                    "fps": 30}
            ours, theirs = local.evaluate(body), remote.evaluate(body)
            assert ours["error"] == pytest.approx(theirs["error"], abs=1e-12)
            assert ours["power_w"] == pytest.approx(theirs["power_w"], rel=1e-12)
            # power priced at the path's resolution, scaled once where the frame is evaluated
            scaled = {**body, "power_resolution": [1280, 720]}
            big_ours, big_theirs = local.evaluate(scaled), remote.evaluate(scaled)
            assert big_ours["error"] == pytest.approx(ours["error"], abs=1e-12)
            assert big_ours["power_w"] > ours["power_w"]
            for key in ("power_w", "frame_time_s"):
                assert big_ours[key] == pytest.approx(big_theirs[key], rel=1e-12), key
            for fmt in ("png", "exr"):
                img_ours = local.render({**body, "format": fmt})
                img_theirs = remote.render({**body, "format": fmt})
                assert img_ours.content_type == img_theirs.content_type
                assert img_ours.data == img_theirs.data  # same pixels, one encoder (sim_core.image)
                assert img_ours.metadata["energy"]["power_w"] == pytest.approx(
                    img_theirs.metadata["energy"]["power_w"], rel=1e-9)
    with pytest.raises(ValueError, match="not a value of 'sampling'"):
        local.evaluate({**body, "settings": {"sampling": "nonsense"}})
    for bad in ([0, 720], [1280], "1280x720", [1280.5, 720]):
        with pytest.raises(ValueError, match="power_resolution"):
            local.evaluate({**body, "power_resolution": bad})


def test_local_job_gives_the_in_process_store(glb: Path, tmp_path: Path) -> None:
    from service.eval_cache import EvalCache
    from service.evaluation import load_scene
    from service.executors import InProcessExecutor
    from service.jobs import run_optimisation

    client = LocalClient(tmp_path / "data")
    scene_id = client.upload_scene(glb)["id"]
    spec = tiny_job(scene_id)
    job = client.submit_job(spec)
    deadline = time.monotonic() + 120
    states = set()
    while (state := client.job(job["id"]))["state"] not in ("done", "failed", "cancelled"):
        states.add(state["state"])
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert state["state"] == "done", state
    text = client.store_text(state["store_id"])
    assert not (tmp_path / "data" / "jobs" / job["id"]).exists()  # handed over, folder cleaned
    with EvalCache(tmp_path / "reference.sqlite3") as cache:
        reference = run_optimisation(spec, scene=load_scene(glb), cache=cache, executor=InProcessExecutor(),
                                     progress=lambda p: None, should_cancel=lambda: False)
    assert comparable(text) == comparable(reference.to_json())
    assert client.job_pids() == []


def test_run_job_reports_progress_and_a_second_run_is_served_from_the_cache(glb: Path, tmp_path: Path
                                                                           ) -> None:
    client = LocalClient(tmp_path / "data", workers=2)
    options = JobRequest(parameters=("sampling", "max_depth"),
                         options={"max_depth": 0, "population": 4, "generations": 2, "exhaustive_limit": 64,
                                  "eval_width": 16, "eval_height": 12})
    updates = []
    first = run_job(client, glb, camera_path(3), options, progress=updates.append, poll_s=0.05)
    assert updates[0].state == "uploading" and updates[-1].state == "done" and updates[-1].fraction == 1.0
    assert first.scene_info["stats"]["triangles"] == 14
    again = run_job(client, glb, camera_path(3), options, poll_s=0.05)
    assert comparable(again.store_text) == comparable(first.store_text)
    meta = json.loads(again.store_text)["meta"]
    assert meta["evaluations"] == 0 and meta["cache_hits"] > 0


def test_cancel_stops_the_job_and_keeps_its_evaluations(tmp_path: Path) -> None:
    glb = tmp_path / "teapot.glb"
    glb.write_bytes(teapot_scene_glb())
    client = LocalClient(tmp_path / "data")
    options = JobRequest(options={"view_sampling": "aimed", "max_depth": 2, "population": 16,
                                  "generations": 20, "eval_width": 48, "eval_height": 36})
    seen: list[Any] = []

    def cancel_when_running() -> bool:
        return any(u.state == "running" and "evaluations" in u.text and not u.text.endswith(" 0 evaluations")
                   for u in seen)

    with pytest.raises(JobCancelled):
        run_job(client, glb, camera_path(3), options, progress=seen.append, should_cancel=cancel_when_running,
                poll_s=0.05)
    assert client.wait_idle(30)
    cache = tmp_path / "data" / "cache" / "eval_cache.sqlite3"
    assert cache.is_file() and cache.stat().st_size > 0
    jobs = tmp_path / "data" / "jobs"  # and nothing of the cancelled job is left in the data folder
    deadline = time.monotonic() + 10
    while list(jobs.iterdir()) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert list(jobs.iterdir()) == []


def test_a_killed_job_leaves_no_camera_references_behind(tmp_path: Path) -> None:
    """Closing the client (the add-on disabled, Blender quitting) kills a running job at once, before its
    own clean-up runs; its camera references were in its own folder, which the client removes."""
    glb = tmp_path / "teapot.glb"
    glb.write_bytes(teapot_scene_glb())
    client = LocalClient(tmp_path / "data")
    spec = tiny_job(client.upload_scene(glb)["id"], resolution=(48, 36), depth_values=(0, 1, 2))
    spec["options"].update(max_depth=2, population=64, generations=500, exhaustive_limit=0,
                           view_sampling="aimed")
    job = client.submit_job(spec)
    jobs = tmp_path / "data" / "jobs"
    deadline = time.monotonic() + 120
    while not list(jobs.glob("*/scratch/render-budget-references-*")):
        assert time.monotonic() < deadline and client.job(job["id"])["state"] in ("queued", "running")
        time.sleep(0.02)
    client.close()
    assert client.job(job["id"])["state"] == "cancelled" and not client.job_pids()
    assert list(jobs.glob("*/scratch")) == [] and not (jobs / job["id"]).exists()  # nor its folder


def test_a_failing_job_says_why(glb: Path, tmp_path: Path) -> None:
    client = LocalClient(tmp_path / "data")
    scene_id = client.upload_scene(glb)["id"]
    spec = tiny_job(scene_id)
    spec["parameters"] = ["no_such_parameter"]
    job = client.submit_job(spec)
    deadline = time.monotonic() + 60
    while client.job(job["id"])["state"] not in ("done", "failed", "cancelled"):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    state = client.job(job["id"])
    assert state["state"] == "failed" and "no_such_parameter" in state["error"]
    with pytest.raises(JobFailed, match="no_such_parameter"):
        run_job(client, glb, camera_path(3), JobRequest(parameters=("no_such_parameter",)), poll_s=0.05)


PARENT = textwrap.dedent("""
    import json, sys, time
    from pathlib import Path
    from addon.core.local_jobs import LocalClient
    from tests.api_support import teapot_scene_glb, tiny_job
    data = Path(sys.argv[1])
    glb = data / "teapot.glb"
    glb.write_bytes(teapot_scene_glb())
    client = LocalClient(data / "data", workers=2)
    spec = tiny_job(client.upload_scene(glb)["id"], resolution=(48, 36), depth_values=(0, 1, 2, 3))
    spec["options"].update(max_depth=2, population=16, generations=20, view_sampling="aimed")
    job = client.submit_job(spec)
    while not (client.job(job["id"]).get("progress") or {}).get("evaluations"):
        assert client.job(job["id"])["state"] in ("queued", "running"), client.job(job["id"])
        time.sleep(0.05)
    print("RUNNING", flush=True)
    time.sleep(600)
""")


def test_the_job_and_its_workers_die_with_their_parent(tmp_path: Path) -> None:
    """Blender killed mid-job (SIGKILL: no clean-up code runs) leaves no process behind."""
    if not sys.platform.startswith("linux"):
        pytest.skip("reads /proc")
    parent = subprocess.Popen([sys.executable, "-c", PARENT, str(tmp_path)], stdout=subprocess.PIPE,
                              text=True, cwd=Path(__file__).resolve().parent.parent)
    try:
        assert parent.stdout.readline().strip() == "RUNNING"
        kill_and_check_nothing_left(parent, descendants(parent.pid))
    finally:
        if parent.poll() is None:
            parent.kill()


def test_job_command_isolates_the_child_from_the_users_python_environment() -> None:
    cmd = job_command("/opt/blender/python/bin/python3.11", ["--request", "r.json"])
    assert cmd[:3] == ["/opt/blender/python/bin/python3.11", "-I", "-c"]
    assert "service.local_job" in cmd[3] and cmd[4:] == ["--request", "r.json"]


def test_a_job_that_cannot_start_says_what_to_do(glb: Path, tmp_path: Path) -> None:
    client = LocalClient(tmp_path / "data", python=tmp_path / "no-such-python")
    scene_id = client.upload_scene(glb)["id"]
    with pytest.raises(RuntimeError, match=r"could not start a local job .* remote service"):
        client.submit_job(tiny_job(scene_id))
    assert client.job_pids() == []
