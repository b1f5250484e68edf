"""The service's durable state (service.storage) and the job manager's restart rules, without a server."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from service.jobs import JobManager, SceneCache, progress_dict
from service.storage import Conflict, Storage, is_hex_id

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
    events = storage.events_after(job_id=job.id)
    assert [e.seq for e in events] == list(range(1, 82)) and events[0].kind == "queued"
    assert sorted(e.data["i"] for e in events[1:] if e.data["writer"] == 2) == list(range(20))
    storage.update_job(job_id=job.id, state="done", store_id="s", event=("done", {"state": "done"}))
    # The finished job keeps its state changes and its last progress event, numbers unchanged.
    assert [(e.seq, e.kind) for e in storage.events_after(job_id=job.id)] == [
        (1, "queued"), (81, "progress"), (82, "done")]
    assert storage.events_after(job_id=job.id)[1].data == events[-1].data
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
    # the whole job's fraction: a resumed attempt starts over, the job's fraction does not
    assert progress_dict(Progress(fraction=0.25), elapsed_s=1.0)["fraction"] == 0.25
    assert progress_dict(Progress(fraction=0.25), elapsed_s=1.0, fraction_before=0.5)["fraction"] == 0.5
    assert progress_dict(Progress(fraction=0.75), elapsed_s=1.0, fraction_before=0.5)["fraction"] == 0.75
    assert progress_dict(Progress(fraction=1.0, phase="done"), elapsed_s=1.0, fraction_before=0.5)[
        "fraction"] == 1.0
    assert progress_dict(Progress(fraction=0.25), elapsed_s=1.0, fraction_before=1.0)["fraction"] < 1.0
    assert "fraction" not in progress_dict({"views_done": 1}, elapsed_s=1.0)  # an optimiser without it


def test_progress_after_every_view_does_not_promise_no_time_left() -> None:
    """Every view searched, the display pricing's bridging still to come and the optimiser without a
    time left yet (a round answered from the evaluation cache): the job's time left is unknown, not the
    views' pace (0 s: a 640x360 rerun showed "~0 s left" for its whole bridging). Done, it is 0."""
    from service.optimize import Progress

    bridging = Progress(views_done=46, views_planned=46, elapsed_s=17.0, fraction=0.39,
                        phase="price between the priced points")
    assert progress_dict(bridging, elapsed_s=17.0)["estimate_s"] is None
    timed = Progress(views_done=46, views_planned=46, elapsed_s=17.0, fraction=0.39, estimate_s=600.0)
    assert progress_dict(timed, elapsed_s=17.0)["estimate_s"] == 600.0
    done = Progress(views_done=46, views_planned=46, elapsed_s=90.0, fraction=1.0, phase="done")
    assert progress_dict(done, elapsed_s=90.0)["estimate_s"] == 0.0
    assert progress_dict({"views_done": 4, "views_planned": 4}, elapsed_s=1.0)["estimate_s"] == 0.0


def _run_with(storage: Storage, monkeypatch, job_id: str, attempt) -> None:
    """The job manager runs ``job_id`` with ``attempt`` in place of the optimiser (no scene, no workers)."""
    import service.jobs as jobs_module

    monkeypatch.setattr(jobs_module, "run_optimisation", attempt)
    monkeypatch.setattr(jobs_module, "SceneHandle", lambda *_a, **_kw: None)
    manager = JobManager(storage, SceneCache(storage), workers=0)
    monkeypatch.setattr(manager.scenes, "get", lambda _id: None)
    monkeypatch.setattr(manager, "executor", lambda: None)
    monkeypatch.setattr(manager, "eval_cache", lambda: None)
    manager._run(job_id)


def test_a_resumed_job_keeps_the_fraction_an_earlier_attempt_reached(storage: Storage, monkeypatch) -> None:
    """The job manager passes the stored progress's fraction on to the next attempt's reports."""
    from service.optimize import Cancelled, Progress

    job = storage.create_job(scene_id=SCENE, spec={})
    storage.update_job(job_id=job.id, progress={"views_done": 3, "fraction": 0.5})

    def attempt(spec, *, progress, **_kw):  # the second attempt: the optimiser starts over
        for f in (0.125, 0.625):
            progress(Progress(fraction=f))
        raise Cancelled("stopped")

    _run_with(storage, monkeypatch, job.id, attempt)
    reported = [e.data["fraction"] for e in storage.events_after(job_id=job.id) if e.kind == "progress"]
    assert reported == [0.5, 0.625]
    assert storage.get_job(job_id=job.id).progress["fraction"] == 0.625


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


def test_listings_are_newest_first_in_stable_pages(storage: Storage) -> None:
    jobs = [storage.create_job(scene_id=SCENE, spec={"n": i}) for i in range(7)]
    seen, cursor = [], None
    while True:
        page = storage.page_jobs(limit=3, cursor=cursor)
        seen += [j.id for j in page.items]
        if page.next_cursor is None:
            break
        cursor = page.next_cursor
        storage.create_job(scene_id=SCENE, spec={"late": True})  # newer rows never shift later pages
    assert seen == [j.id for j in reversed(jobs)]
    storage.update_job(job_id=jobs[0].id, state="done")
    assert [j.id for j in storage.page_jobs(state="done").items] == [jobs[0].id]
    assert storage.page_jobs(scene_id="cd" * 32).items == []
    for bad in ("garbage", "W10", "WyJ4IiwgMV0", "W251bGwsICJhIl0"):  # not ours, [], ["x", 1], [null, "a"]
        with pytest.raises(ValueError, match="cursor"):
            storage.page_jobs(cursor=bad)
    with pytest.raises(ValueError):
        storage.list_scenes(limit=0)
    assert [s.id for s in storage.list_scenes().items] == [SCENE]


def test_deleting_a_scene_waits_for_its_jobs_and_keeps_its_stores(storage: Storage) -> None:
    path = storage.scene_path(SCENE)
    path.write_bytes(b"glTF")
    job = storage.create_job(scene_id=SCENE, spec={})
    storage.append_event(job_id=job.id, kind="progress", data={})
    with pytest.raises(Conflict, match="queued or running"):
        storage.delete_scene(scene_id=SCENE)
    storage.update_job(job_id=job.id, state="running")
    with pytest.raises(Conflict):
        storage.delete_scene(scene_id=SCENE)
    store = storage.put_store(scene_id=SCENE, job_id=job.id, body="{}")
    storage.update_job(job_id=job.id, state="done", store_id=store)
    assert storage.delete_scene(scene_id=SCENE) is True
    assert storage.get_scene(scene_id=SCENE) is None and not path.exists()
    assert storage.get_job(job_id=job.id) is None and storage.events_after(job_id=job.id) == []
    assert storage.get_store(store_id=store).body == "{}"  # the result outlives its scene
    assert storage.delete_scene(scene_id=SCENE) is False
    with pytest.raises(KeyError):  # a job for a scene that is gone
        storage.create_job(scene_id=SCENE, spec={})


def test_deleting_jobs_and_stores(storage: Storage) -> None:
    job = storage.create_job(scene_id=SCENE, spec={})
    with pytest.raises(Conflict, match="cancel it first"):
        storage.delete_job(job_id=job.id)
    storage.request_cancel(job_id=job.id)
    assert storage.delete_job(job_id=job.id) is True and storage.get_job(job_id=job.id) is None
    assert storage.delete_job(job_id=job.id) is False
    store = storage.put_store(scene_id=SCENE, job_id="j", body='{"x": 1}')
    listed = storage.list_stores().items
    assert [s.id for s in listed] == [store] and listed[0].body == "" and listed[0].size == 8
    assert storage.delete_store(store_id=store) is True and storage.get_store(store_id=store) is None
    assert storage.delete_store(store_id=store) is False


def test_active_scene_hashes_name_what_eviction_must_keep(storage: Storage) -> None:
    other = "ef" * 32
    storage.add_scene(scene_id=other, size=1, content_hash="d", stats={}, inert={}, cameras=0)
    a = storage.create_job(scene_id=SCENE, spec={})
    b = storage.create_job(scene_id=other, spec={})
    assert sorted(storage.active_scene_hashes()) == ["c", "d"]
    storage.update_job(job_id=a.id, state="done")
    storage.update_job(job_id=b.id, state="running")
    assert storage.active_scene_hashes() == ["d"]


def test_a_job_keeps_its_camera_references_in_its_own_folder_until_it_ends(storage: Storage,
                                                                           monkeypatch) -> None:
    """The optimiser gets the job's own folder in the data directory for the references its pricing
    rounds share: an interrupted attempt (the service stopping) leaves it for the resumed one, a start
    keeps only the re-queued jobs' folders, and the job's end removes it."""
    from service.optimize import Cancelled

    job = storage.create_job(scene_id=SCENE, spec={})
    seen: list[object] = []

    def interrupted(spec, *, references_dir, **_kw):
        seen.append(references_dir)
        references_dir.mkdir(parents=True)  # (as optimize_path does)
        (references_dir / "frame-x.npz").write_bytes(b"a reference")
        raise Cancelled("stopped")  # no cancel was asked for: the service is stopping

    _run_with(storage, monkeypatch, job.id, interrupted)
    folder = storage.references_dir / job.id
    assert seen == [folder] and (folder / "frame-x.npz").is_file()
    assert storage.get_job(job_id=job.id).state == "queued"

    stray = storage.references_dir / ("ab" * 16)  # a job that ended while no service ran
    stray.mkdir()
    (stray / "frame-y.npz").write_bytes(b"another")
    manager = JobManager(storage, SceneCache(storage), workers=0)
    manager.start()
    assert (folder / "frame-x.npz").is_file() and not stray.exists()
    manager.stop()

    def resumed(spec, *, references_dir, **_kw):
        seen.append(references_dir)
        assert (references_dir / "frame-x.npz").read_bytes() == b"a reference"
        raise RuntimeError("broken")

    _run_with(storage, monkeypatch, job.id, resumed)
    assert seen == [folder, folder] and storage.get_job(job_id=job.id).state == "failed"
    assert not folder.exists()
    with pytest.raises(ValueError):
        storage.job_references("../scenes")
