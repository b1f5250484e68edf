"""Jobs end to end on a real uvicorn server: upload the teapot, optimise, stream events, query the store;
concurrent jobs, queries during a job, cancellation, previews and evaluations."""

from __future__ import annotations

import base64
import io
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from api_support import camera_path, look_at_matrix, server_thread, sse_events, teapot_scene_glb, tiny_job

from service.api import Settings
from service.store import ParetoStore

pytestmark = pytest.mark.service

GLB = {"Content-Type": "model/gltf-binary"}


def wait_job(client: httpx.Client, job_id: str, states: set[str], timeout: float = 120.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/jobs/{job_id}").json()
        if job["state"] in states:
            return job
        time.sleep(0.05)
    raise TimeoutError(f"job {job_id} not in {states} after {timeout} s: {job}")


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("api-jobs")


@pytest.fixture(scope="module")
def base(data_dir: Path) -> Iterator[str]:
    with server_thread(Settings(data_dir=data_dir, job_workers=2)) as url:
        yield url


@pytest.fixture(scope="module")
def client(base: str) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=base, timeout=120.0) as c:
        yield c


@pytest.fixture(scope="module")
def scene(client: httpx.Client) -> dict[str, Any]:
    r = client.post("/scenes", content=teapot_scene_glb(), headers=GLB)
    assert r.status_code == 201, r.text
    return r.json()


@pytest.fixture(scope="module")
def finished(client: httpx.Client, scene: dict[str, Any]) -> dict[str, Any]:
    """One tiny job run to completion, with its full event stream."""
    r = client.post("/jobs", json=tiny_job(scene["id"]))
    assert r.status_code == 201, r.text
    job = r.json()
    events = sse_events(client, f"/jobs/{job['id']}/events")
    return {"job": client.get(f"/jobs/{job['id']}").json(), "events": events}


def test_upload_reports_stats_and_inert_parameters(client: httpx.Client, scene: dict[str, Any],
                                                   data_dir: Path) -> None:
    assert len(scene["id"]) == 64
    assert scene["stats"]["triangles"] > 6000  # teapot + ground
    assert scene["stats"]["lights"] == 1
    assert isinstance(scene["inert_parameters"], dict)
    # No transmissive material in the scene: refraction cannot matter; whatever is inert says why.
    assert all(isinstance(v, str) and v for v in scene["inert_parameters"].values())
    assert (data_dir / "scenes" / f"{scene['id']}.glb").is_file()
    again = client.post("/scenes", content=teapot_scene_glb(), headers=GLB)
    assert again.json()["id"] == scene["id"]
    assert client.get(f"/scenes/{scene['id']}").json() == scene


def test_job_end_to_end_events_store_and_query(client: httpx.Client, finished: dict[str, Any]) -> None:
    job, events = finished["job"], finished["events"]
    assert job["state"] == "done", job
    kinds = [k for k, _ in events]
    assert kinds[0] == "queued" and kinds[-1] == "done"
    assert "started" in kinds and "progress" in kinds
    seqs = [d["seq"] for _, d in events]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    done = [d["views_done"] for k, d in events if k == "progress"]
    assert done == sorted(done) and done[-1] > 0
    assert job["progress"]["evaluations"] > 0
    assert events[-1][1]["store_id"] == job["store_id"]

    r = client.get(f"/stores/{job['store_id']}")
    assert r.status_code == 200
    store = ParetoStore.from_json(r.text)
    names = [p.name for p in store.parameters]

    frame = camera_path(3)["frames"][1]
    m = np.asarray(frame["matrix_world"])
    query = {"position": m[:3, 3].tolist(), "matrix": frame["matrix_world"], "fov": frame["vfov"]}
    cheap = client.post(f"/stores/{job['store_id']}/query", json={**query, "power_budget_w": 1e-6}).json()
    rich = client.post(f"/stores/{job['store_id']}/query", json={**query, "power_budget_w": 1e4}).json()
    assert set(cheap["settings"]) == set(names)
    assert cheap["infeasible"] is True and rich["infeasible"] is False
    assert rich["error"] <= cheap["error"] and rich["power_w"] >= cheap["power_w"]
    assert cheap["clamped"] is False
    # Same answer as the store module itself.
    direct = store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], power_budget=1e4)
    assert rich["packed"] == direct.packed and rich["indices"] == list(direct.indices)
    wide = client.post(f"/stores/{job['store_id']}/query",
                       json={**query, "aspect": 3.0, "power_budget_w": 0.5}).json()
    assert wide["packed"] == store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], power_budget=0.5,
                                          aspect=3.0).packed

    by_error = client.post(f"/stores/{job['store_id']}/query", json={**query, "error_budget": 1.0}).json()
    assert by_error["power_w"] <= rich["power_w"]
    outside = client.post(f"/stores/{job['store_id']}/query",
                          json={"position": [100.0, 0.0, 0.0], "direction": [-1, 0, 0], "error_budget": 0.5})
    assert outside.status_code == 200 and outside.json()["clamped"] is True

    # Temporal filter: half-way through the period from the cheap to the rich settings.
    prev = {"indices": cheap["indices"], "elapsed_s": 1.0, "period_s": 2.0}
    mid = client.post(f"/stores/{job['store_id']}/query",
                      json={**query, "power_budget_w": 1e4, "previous": prev}).json()
    expect = [int(np.floor(0.5 * a + 0.5 * b + 0.5)) for a, b in zip(cheap["indices"], rich["indices"],
                                                                      strict=True)]
    assert mid["indices"] == expect
    assert mid["filtered"] == (expect != rich["indices"])
    late = client.post(f"/stores/{job['store_id']}/query",
                       json={**query, "power_budget_w": 1e4, "previous": {**prev, "elapsed_s": 5.0}}).json()
    assert late["indices"] == rich["indices"] and late["filtered"] is False
    bad = client.post(f"/stores/{job['store_id']}/query",
                      json={**query, "power_budget_w": 1.0, "previous": {**prev, "indices": [0]}})
    assert bad.status_code == 422


def test_events_can_be_replayed_after_the_end(client: httpx.Client, finished: dict[str, Any]) -> None:
    job = finished["job"]
    again = sse_events(client, f"/jobs/{job['id']}/events")
    assert [k for k, _ in again] == [k for k, _ in finished["events"]]
    last_two = finished["events"][-2][1]["seq"]
    tail = []
    with client.stream("GET", f"/jobs/{job['id']}/events", headers={"Last-Event-ID": str(last_two)}) as r:
        tail = [line for line in r.iter_lines() if line.startswith("event:")]
    assert tail == ["event: done"]


def test_two_concurrent_jobs_and_queries_during_them(client: httpx.Client, scene: dict[str, Any],
                                                     finished: dict[str, Any]) -> None:
    store_id = finished["job"]["store_id"]
    query = {"position": [0.0, -3.0, 1.5], "direction": [0.0, 1.0, -0.3], "error_budget": 0.05}
    expected = client.post(f"/stores/{store_id}/query", json=query).json()
    # New resolutions: nothing in the evaluation cache, so both jobs really render.
    a = client.post("/jobs", json=tiny_job(scene["id"], resolution=(160, 120))).json()
    b = client.post("/jobs", json=tiny_job(scene["id"], resolution=(176, 132))).json()
    answers: list[dict[str, Any]] = []
    both_running = False
    stop = threading.Event()

    def watch() -> None:
        nonlocal both_running
        with httpx.Client(base_url=str(client.base_url), timeout=30) as c:
            while not stop.is_set():
                states = {c.get(f"/jobs/{j['id']}").json()["state"] for j in (a, b)}
                both_running |= states == {"running"}
                time.sleep(0.02)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        while True:
            r = client.post(f"/stores/{store_id}/query", json=query)
            assert r.status_code == 200
            answers.append(r.json())
            states = {client.get(f"/jobs/{j['id']}").json()["state"] for j in (a, b)}
            if states <= {"done", "failed", "cancelled"}:
                break
    finally:
        stop.set()
        watcher.join()
    ja, jb = (client.get(f"/jobs/{j['id']}").json() for j in (a, b))
    assert ja["state"] == jb["state"] == "done", (ja, jb)
    assert both_running or (ja["started"] < jb["finished"] and jb["started"] < ja["finished"])
    assert len(answers) >= 2 and all(x == expected for x in answers)
    assert ja["store_id"] != jb["store_id"]


def test_cancel_mid_job(client: httpx.Client, scene: dict[str, Any]) -> None:
    spec = tiny_job(scene["id"], resolution=(40, 30), depth_values=(0, 1, 2))
    # the paper's view cubes split twice: far more work than this 3-frame path's few path samples, so
    # the job is still running when the cancel arrives
    spec["options"].update(max_depth=2, view_sampling="aimed")
    job = client.post("/jobs", json=spec).json()
    wait_job(client, job["id"], {"running", "done"})
    deadline = time.monotonic() + 60
    while client.get(f"/jobs/{job['id']}").json()["progress"]["evaluations"] == 0:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    r = client.delete(f"/jobs/{job['id']}")
    assert r.status_code == 200 and r.json()["cancel_requested"] is True
    events = sse_events(client, f"/jobs/{job['id']}/events")
    assert events[-1][0] == "cancelled"
    final = client.get(f"/jobs/{job['id']}").json()
    assert final["state"] == "cancelled" and final["store_id"] is None
    assert client.delete(f"/jobs/{job['id']}").status_code == 200  # idempotent


def test_cancel_of_a_finished_job_is_409(client: httpx.Client, finished: dict[str, Any]) -> None:
    r = client.delete(f"/jobs/{finished['job']['id']}")
    assert r.status_code == 409 and r.json()["error"]["code"] == "conflict"


def test_job_request_errors_name_the_problem(client: httpx.Client, scene: dict[str, Any]) -> None:
    spec = tiny_job(scene["id"])
    for patch, needle in (({"profile": "nonexistent"}, "profile"),
                          ({"space": {"sampling": ["ultra"]}}, "ultra"),
                          ({"parameters": ["warp_drive"]}, "warp_drive")):
        r = client.post("/jobs", json={**spec, **patch})
        assert r.status_code == 422, r.text
        assert needle in r.json()["error"]["message"]


# -- render and evaluate --------------------------------------------------------------------------------
def camera(width: int = 32, height: int = 24) -> dict[str, Any]:
    return {"matrix_world": look_at_matrix((0.0, -3.0, 1.5), (0.0, 0.0, 0.4)), "vfov": 0.7,
            "width": width, "height": height}


def test_render_png_preview_with_counters_and_energy(client: httpx.Client, scene: dict[str, Any]) -> None:
    from PIL import Image

    r = client.post("/render", json={"scene_id": scene["id"], "camera": camera(),
                                     "settings": {"max_depth": 1, "sampling": "1spp"}})
    assert r.status_code == 200, r.text
    body = r.json()
    img = Image.open(io.BytesIO(base64.b64decode(body["image_base64"])))
    assert img.format == "PNG" and img.size == (32, 24)
    assert np.asarray(img).std() > 0  # the teapot is visible, not a blank frame
    assert body["counters"]["rays_primary"] > 0 and body["counters"]["pixels"] == 32 * 24
    assert body["energy"]


def test_render_exr_preview(client: httpx.Client, scene: dict[str, Any]) -> None:
    r = client.post("/render", json={"scene_id": scene["id"], "camera": camera(16, 12), "format": "exr"})
    assert r.status_code == 200, r.text
    data = base64.b64decode(r.json()["image_base64"])
    assert data[:4] == b"\x76\x2f\x31\x01"  # OpenEXR magic


def test_evaluate_reference_and_cheap_settings(client: httpx.Client, scene: dict[str, Any]) -> None:
    best = client.post("/evaluate", json={"scene_id": scene["id"], "camera": camera()}).json()
    assert best["error"] == 0.0 and best["power_w"] > 0
    cheap = client.post("/evaluate", json={"scene_id": scene["id"], "camera": camera(),
                                           "settings": {"sampling": "undersample_4x4", "max_depth": 0,
                                                        "shadow_samples": 0, "ao_samples": 0}}).json()
    assert 0.0 < cheap["error"] < 1.0 and cheap["power_w"] < best["power_w"]
    r = client.post("/evaluate", json={"scene_id": scene["id"], "camera": camera(),
                                       "settings": {"max_depth": 7}})
    assert r.status_code == 422 and "max_depth" in r.json()["error"]["message"]
    r = client.post("/render", json={"scene_id": "0" * 64, "camera": camera()})
    assert r.status_code == 404


def test_query_fast_path_matches_the_fastapi_route(client: httpx.Client, finished: dict[str, Any],
                                                   tmp_path: Path) -> None:
    from service.storage import Storage

    store_id = finished["job"]["store_id"]
    body = client.get(f"/stores/{store_id}").text
    storage = Storage(tmp_path)
    assert storage.put_store(scene_id="0" * 64, job_id="copy", body=body) == store_id
    storage.close()
    rng = np.random.default_rng(3)
    queries: list[Any] = []
    for _ in range(12):
        q: dict[str, Any] = {"position": rng.uniform(-4, 4, 3).tolist(),
                             "direction": rng.normal(size=3).tolist(), "fov": float(rng.uniform(0.3, 1.2))}
        q["power_budget_w" if rng.random() < 0.5 else "error_budget"] = float(rng.uniform(0, 1))
        queries.append(q)
    n = len(ParetoStore.from_json(body).parameters)
    queries.append({**queries[0], "previous": {"indices": [0] * n, "elapsed_s": 0.7}})
    queries.append({**queries[0], "previous": {"indices": [15] * n, "elapsed_s": 0.7}})  # out of range
    queries.append({**queries[0], "error_budget": 0.1, "power_budget_w": 1.0})
    queries.append({"position": "here", "error_budget": 0.1})
    raw = [b'{"position": [0, NaN, 0], "error_budget": 0.1}', b'{"position": [0, 0', b"[]"]
    with server_thread(Settings(data_dir=tmp_path, query_fast_path=False, job_workers=1)) as slow_url, \
            httpx.Client(base_url=slow_url) as slow:
        for target in (store_id, "f" * 32):
            for q in queries:
                a = client.post(f"/stores/{target}/query", json=q)
                b = slow.post(f"/stores/{target}/query", json=q)
                assert a.status_code == b.status_code, (q, a.text, b.text)
                if a.status_code == 200:
                    assert a.json() == b.json()
                else:
                    assert a.json()["error"]["code"] == b.json()["error"]["code"]
            for data in raw:
                headers = {"Content-Type": "application/json"}
                a = client.post(f"/stores/{target}/query", content=data, headers=headers)
                b = slow.post(f"/stores/{target}/query", content=data, headers=headers)
                assert a.status_code == b.status_code == 422, (data, a.text, b.text)


def test_extreme_but_finite_orientations_are_answered(client: httpx.Client, finished: dict[str, Any]) -> None:
    """Found by the fuzzer: huge direction components overflowed the store's normalisation (a 500)."""
    store_id = finished["job"]["store_id"]
    url = f"/stores/{store_id}/query"
    small = client.post(url, json={"position": [0, -3, 1.5], "direction": [0, 0, 1], "error_budget": 0.0})
    huge = client.post(url, json={"position": [0, -3, 1.5], "direction": [0, 0, 1.34e154],
                                  "error_budget": 0.0})
    assert huge.status_code == 200 and huge.json() == small.json()
    m = look_at_matrix((0.0, -3.0, 1.5), (0.0, 0.0, 0.4))
    scaled = [[c * 1e150 if j < 3 else c for j, c in enumerate(row)] for row in m[:3]] + [m[3]]
    a = client.post(url, json={"position": [0, -3, 1.5], "matrix": m, "power_budget_w": 1.0})
    b = client.post(url, json={"position": [0, -3, 1.5], "matrix": scaled, "power_budget_w": 1.0})
    assert a.status_code == b.status_code == 200 and a.json() == b.json()
