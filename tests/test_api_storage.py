"""The service's durable state (service.storage) and the job manager's restart rules, without a server."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from service.jobs import JobManager, SceneCache, progress_dict
from service.storage import Storage, is_hex_id

SCENE = "ab" * 32


@pytest.fixture
def storage(tmp_path: Path) -> Storage:
    s = Storage(tmp_path)
    s.add_scene(scene_id=SCENE, size=10, content_hash="c", stats={"triangles": 2}, inert={}, cameras=0)
    yield s
    s.close()


def test_wal_and_layout(storage: Storage, tmp_path: Path) -> None:
    assert storage.journal_mode() == "wal"
    assert {p.name for p in tmp_path.iterdir()} >= {"scenes", "tmp", "service.sqlite3"}
    assert storage.eval_cache_path.parent == tmp_path


def test_leftover_uploads_are_removed_at_start(tmp_path: Path) -> None:
    Storage(tmp_path).close()
    (tmp_path / "tmp" / "half.glb").write_bytes(b"glTF")
    Storage(tmp_path).close()
    assert list((tmp_path / "tmp").iterdir()) == []


def test_scene_files_are_content_addressed_and_never_paths(storage: Storage) -> None:
    tmp = storage.new_temp_path(".glb")
    tmp.write_bytes(b"data")
    path = storage.adopt_scene_file(temp_path=tmp, scene_id=SCENE)
    assert path == storage.scenes_dir / f"{SCENE}.glb" and path.read_bytes() == b"data"
    again = storage.new_temp_path(".glb")
    again.write_bytes(b"data")
    assert storage.adopt_scene_file(temp_path=again, scene_id=SCENE) == path and not again.exists()
    for bad in ("../" + SCENE[3:], SCENE.upper(), SCENE[:-1], "/etc/passwd"):
        with pytest.raises(ValueError):
            storage.scene_path(bad)
    assert is_hex_id(SCENE, 64) and not is_hex_id(SCENE + "0", 64)


def test_job_events_are_ordered_and_atomic_with_state(storage: Storage) -> None:
    job = storage.create_job(scene_id=SCENE, spec={"x": 1})
    assert job.state == "queued" and job.spec == {"x": 1}

    def writer(k: int) -> None:
        for i in range(20):
            storage.append_event(job_id=job.id, kind="progress", data={"writer": k, "i": i})

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    storage.update_job(job_id=job.id, state="done", store_id="s", event=("done", {"state": "done"}))
    events = storage.events_after(job_id=job.id)
    assert [e.seq for e in events] == list(range(1, 83))
    assert events[0].kind == "queued" and events[-1].kind == "done"
    assert [e.seq for e in storage.events_after(job_id=job.id, after_seq=80)] == [81, 82]
    assert storage.get_job(job_id=job.id).state == "done"
    with pytest.raises(ValueError):  # NaN never reaches the database
        storage.append_event(job_id=job.id, kind="progress", data={"v": float("nan")})


def test_cancel_queued_is_immediate_and_running_is_a_request(storage: Storage) -> None:
    queued = storage.create_job(scene_id=SCENE, spec={})
    running = storage.create_job(scene_id=SCENE, spec={})
    storage.update_job(job_id=running.id, state="running")
    assert storage.request_cancel(job_id=queued.id).state == "cancelled"
    r = storage.request_cancel(job_id=running.id)
    assert r.state == "running" and r.cancel_requested
    assert storage.request_cancel(job_id="missing") is None
    assert storage.count_jobs()["cancelled"] == 1


def test_equal_stores_share_an_id(storage: Storage) -> None:
    a = storage.put_store(scene_id=SCENE, job_id="j1", body='{"a": 1}')
    b = storage.put_store(scene_id=SCENE, job_id="j2", body='{"a": 1}')
    assert a == b and storage.get_store(store_id=a).job_id == "j1"
    assert storage.get_store(store_id="nope") is None


def test_restart_requeues_unfinished_jobs(storage: Storage) -> None:
    running = storage.create_job(scene_id=SCENE, spec={})
    storage.update_job(job_id=running.id, state="running", bump_attempts=True)
    queued = storage.create_job(scene_id=SCENE, spec={})
    doomed = storage.create_job(scene_id=SCENE, spec={})
    storage.update_job(job_id=doomed.id, state="running")
    storage.request_cancel(job_id=doomed.id)
    done = storage.create_job(scene_id=SCENE, spec={})
    storage.update_job(job_id=done.id, state="done")

    manager = JobManager(storage, SceneCache(storage), workers=0)  # no threads: inspect the queue only
    manager.start()
    try:
        requeued = []
        while not manager._queue.empty():
            requeued.append(manager._queue.get_nowait())
    finally:
        manager.stop()
    assert requeued == [running.id, queued.id]
    assert storage.get_job(job_id=running.id).state == "queued"
    assert storage.events_after(job_id=running.id)[-1].kind == "resumed"
    assert storage.get_job(job_id=doomed.id).state == "cancelled"
    assert storage.get_job(job_id=done.id).state == "done"


def test_progress_keeps_total_elapsed_and_estimates() -> None:
    from service.optimize import Progress

    p = progress_dict(Progress(views_done=3, views_planned=12, evaluations=40, cache_hits=5, elapsed_s=1.0),
                      elapsed_s=6.0)
    assert p["elapsed_s"] == 6.0 and p["estimate_s"] == 18.0
    assert p["evaluations"] == 40 and p["cache_hits"] == 5 and p["phase"] == "starting"


def test_claim_is_exclusive_and_loses_to_a_cancel(storage: Storage) -> None:
    job = storage.create_job(scene_id=SCENE, spec={})
    claimed = storage.claim_job(job_id=job.id)
    assert claimed is not None and claimed.state == "running" and claimed.attempts == 1
    assert storage.claim_job(job_id=job.id) is None  # a second worker gets nothing
    assert storage.events_after(job_id=job.id)[-1].kind == "started"
    other = storage.create_job(scene_id=SCENE, spec={})
    storage.request_cancel(job_id=other.id)
    assert storage.claim_job(job_id=other.id) is None
    assert storage.get_job(job_id=other.id).state == "cancelled"
