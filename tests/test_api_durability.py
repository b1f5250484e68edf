"""Durability and scale on real processes: SIGKILL mid-job and resume, and a job on a Dask LocalCluster,
each compared with an uninterrupted in-process run of the same request."""

from __future__ import annotations

import json
import signal
import sqlite3
import time
from pathlib import Path
from typing import Any

import httpx
import psutil
import pytest
from api_support import ServerProcess, comparable, server_thread, sse_events, teapot_scene_glb, tiny_job

from service.api import Settings

pytestmark = pytest.mark.service

GLB = {"Content-Type": "model/gltf-binary"}


def cached_evaluations(data_dir: Path) -> int:
    path = data_dir / "eval_cache.sqlite3"
    if not path.exists():
        return 0
    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=30)
    try:
        return int(db.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0])
    except sqlite3.OperationalError:  # created but its table not yet
        return 0
    finally:
        db.close()


def job_state_on_disk(data_dir: Path, job_id: str) -> str:
    db = sqlite3.connect(data_dir / "service.sqlite3", timeout=30)
    try:
        return str(db.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()[0])
    finally:
        db.close()


def small_spec(scene_id: str, sampling: str = "aimed") -> dict[str, Any]:
    """The paper's view cubes (48 root views, then a split): more work on this 3-frame path than path
    sampling, which needs only the frames' few samples."""
    spec = tiny_job(scene_id, resolution=(24, 18), depth_values=(0, 1, 2))
    spec["options"]["max_depth"] = 1
    spec["options"]["view_sampling"] = sampling
    return spec


def durable_spec(scene_id: str) -> dict[str, Any]:
    """A job long enough to be killed mid-way every time: 576 evaluations at 96x72 (a few seconds, many
    committed batches), where the small job is over in about half a second."""
    spec = small_spec(scene_id)
    spec["options"].update(eval_width=96, eval_height=72)
    spec["space"]["shadow_samples"] = [0, 1]
    spec["parameters"].append("shadow_samples")
    return spec


def path_spec(scene_id: str) -> dict[str, Any]:
    return small_spec(scene_id, "path")


def descendants(pid: int) -> list[psutil.Process]:
    return psutil.Process(pid).children(recursive=True)


def wait_gone(processes: list[psutil.Process], timeout: float = 15.0) -> list[psutil.Process]:
    """The processes still alive after ``timeout`` s (zombies count as gone: an orphan's zombie waits
    for whoever reaps orphans here, it renders nothing and holds no memory)."""
    deadline = time.monotonic() + timeout
    alive = processes
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [p for p in alive if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    return alive


def wait_for_evaluations(data_dir: Path, at_least: int, srv: ServerProcess, timeout: float = 120.0) -> int:
    """Poll the evaluation cache file (nothing else in the loop, so the poll keeps up with the job)."""
    deadline = time.monotonic() + timeout
    while (n := cached_evaluations(data_dir)) < at_least:
        assert time.monotonic() < deadline and srv.proc.poll() is None, srv.output()
        time.sleep(0.005)
    return n


def run_uninterrupted(data_dir: Path, spec_of: Any, **settings: Any) -> tuple[dict[str, Any], str, int]:
    with server_thread(Settings(data_dir=data_dir, job_workers=1, **settings)) as url, \
            httpx.Client(base_url=url, timeout=120) as c:
        scene = c.post("/scenes", content=teapot_scene_glb(), headers=GLB).json()
        job = c.post("/jobs", json=spec_of(scene["id"])).json()
        events = sse_events(c, f"/jobs/{job['id']}/events", timeout=300)
        assert events[-1][0] == "done", events[-1]
        final = c.get(f"/jobs/{job['id']}").json()
        body = c.get(f"/stores/{final['store_id']}").text
    return final, body, cached_evaluations(data_dir)


@pytest.mark.slow
def test_sigkill_mid_job_resumes_without_redoing_work(tmp_path: Path) -> None:
    crash_dir, ref_dir = tmp_path / "crash", tmp_path / "reference"
    srv = ServerProcess(crash_dir).wait_healthy()
    try:
        c = httpx.Client(base_url=srv.base_url, timeout=60)
        scene = c.post("/scenes", content=teapot_scene_glb(), headers=GLB).json()
        job = c.post("/jobs", json=durable_spec(scene["id"])).json()
        wait_for_evaluations(crash_dir, 1, srv)  # the first batch is committed: kill now
    finally:
        srv.kill()
    assert job_state_on_disk(crash_dir, job["id"]) == "running"
    done_before = cached_evaluations(crash_dir)

    srv = ServerProcess(crash_dir).wait_healthy()
    try:
        c = httpx.Client(base_url=srv.base_url, timeout=60)
        events = sse_events(c, f"/jobs/{job['id']}/events", timeout=300)
        kinds = [k for k, _ in events]
        assert "resumed" in kinds and kinds[-1] == "done", kinds
        final = c.get(f"/jobs/{job['id']}").json()
        assert final["attempts"] == 2
        resumed_store = c.get(f"/stores/{final['store_id']}").text
    finally:
        srv.stop()

    ref_job, ref_store, ref_evaluations = run_uninterrupted(ref_dir, durable_spec)
    assert comparable(resumed_store) == comparable(ref_store)
    # The resumed attempt rendered exactly what the killed one had not committed.
    assert 0 < done_before < ref_evaluations
    assert final["progress"]["evaluations"] == ref_job["progress"]["evaluations"] - done_before
    assert cached_evaluations(crash_dir) == ref_evaluations


def _scenes_kept() -> list[str]:
    from service import evaluation

    return sorted(evaluation._SCENES)


@pytest.mark.slow
def test_dask_local_cluster_gives_the_in_process_store(tmp_path: Path) -> None:
    from distributed import Client, LocalCluster

    _, local_store, _ = run_uninterrupted(tmp_path / "local", tiny_job)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        _, dask_store, _ = run_uninterrupted(tmp_path / "dask", tiny_job, dask_scheduler=address)
        with server_thread(Settings(data_dir=tmp_path / "dask", dask_scheduler=address)) as url:
            assert httpx.get(f"{url}/health").json()["executor"] == f"dask:{address}"
        # Each worker loaded the scene and keeps it (by content hash) for later batches and jobs.
        with Client(address) as dask_client:
            kept = dask_client.run(_scenes_kept)
        content_hash = json.loads(dask_store)["meta"]["scene"]
        assert len(kept) == 2 and all(v == [content_hash] for v in kept.values()), kept
    assert comparable(dask_store) == comparable(local_store)
    assert json.loads(dask_store)["meta"]["executor"] == "dask"


@pytest.mark.slow
def test_process_pool_service_gives_the_in_process_store(tmp_path: Path) -> None:
    """``--eval-workers 2``: a job's renders run in two local processes; the store (path sampling, the
    default) is the one the in-process service makes."""
    _, local_store, _ = run_uninterrupted(tmp_path / "local", path_spec)
    _, pool_store, _ = run_uninterrupted(tmp_path / "pool", path_spec, eval_workers=2)
    with server_thread(Settings(data_dir=tmp_path / "pool", eval_workers=2)) as url:
        assert httpx.get(f"{url}/health").json()["executor"] == "process-pool:2"
    assert comparable(pool_store) == comparable(local_store)
    doc = json.loads(pool_store)
    assert doc["meta"]["executor"] == "process-pool" and doc["meta"]["view_sampling"] == "path"
    assert "frontier_eyes" in doc and "frontier_dirs" in doc


@pytest.mark.slow
@pytest.mark.parametrize("signal_name", ["SIGKILL", "SIGTERM"])
def test_the_evaluation_workers_die_with_the_service(tmp_path: Path, signal_name: str) -> None:
    """--eval-workers 2 mid-job: killed (SIGKILL: no chance to clean up) or stopped (SIGTERM), the
    service leaves no process behind: neither its pool workers nor multiprocessing's resource tracker."""
    srv = ServerProcess(tmp_path, extra_args=["--eval-workers", "2"]).wait_healthy()
    try:
        c = httpx.Client(base_url=srv.base_url, timeout=60)
        scene = c.post("/scenes", content=teapot_scene_glb(), headers=GLB).json()
        job = c.post("/jobs", json=durable_spec(scene["id"])).json()
        wait_for_evaluations(tmp_path, 1, srv)
        children = descendants(srv.proc.pid)
        workers = [p for p in children if "multiprocessing" in " ".join(p.cmdline())]
        assert len(workers) >= 3, [p.cmdline() for p in children]  # 2 workers + the resource tracker
        srv.proc.send_signal(getattr(signal, signal_name))
        srv.proc.wait(30)
    finally:
        srv.kill()
    assert wait_gone(children) == []
    if signal_name == "SIGTERM":  # a clean stop (uvicorn re-raises the signal once it has shut down)
        assert srv.proc.returncode in (0, -signal.SIGTERM), srv.output()
        assert job_state_on_disk(tmp_path, job["id"]) == "queued"  # interrupted: resumes at the next start
