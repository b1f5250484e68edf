"""Durability and scale on real processes: SIGKILL mid-job and resume, and a job on a Dask LocalCluster,
each compared with an uninterrupted in-process run of the same request."""

from __future__ import annotations

import json
import sqlite3
import time
from pathlib import Path
from typing import Any

import httpx
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


def durable_spec(scene_id: str, sampling: str = "aimed") -> dict[str, Any]:
    """A job long enough to be killed mid-way: the paper's view cubes (48 root views, then a split) do
    more work on this 3-frame path than path sampling, which needs only the frames' few samples."""
    spec = tiny_job(scene_id, resolution=(24, 18), depth_values=(0, 1, 2))
    spec["options"]["max_depth"] = 1
    spec["options"]["view_sampling"] = sampling
    return spec


def path_spec(scene_id: str) -> dict[str, Any]:
    return durable_spec(scene_id, "path")


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
        deadline = time.monotonic() + 120
        while cached_evaluations(crash_dir) < 10:  # some evaluations are committed, the job is not done
            assert time.monotonic() < deadline, srv.output()
            assert c.get(f"/jobs/{job['id']}").json()["state"] in ("queued", "running")
            time.sleep(0.02)
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
