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
from service.store.temporal import blend, transition_period

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
    # the whole job's fraction (search and display pricing), documented in the OpenAPI schema
    progress = [d for k, d in events if k == "progress"]
    fractions = [d["fraction"] for d in progress]
    assert fractions == sorted(fractions) and job["progress"]["fraction"] == 1.0
    assert all(d["fraction"] < 1.0 for d in progress if d["phase"] != "done")
    assert all(d["views_done"] == d["views_planned"] and d["fraction"] < 1.0
               for d in progress if d["phase"] == "price at display resolution")
    schema = client.get("/openapi.json").json()["components"]["schemas"]["JobProgress"]
    assert "display pricing" in schema["properties"]["fraction"]["description"]
    # the phase, declared: a string (null before the first report) naming the pricing phase the events show
    phase = schema["properties"]["phase"]
    assert {t.get("type") for t in phase["anyOf"]} == {"string", "null"}
    assert all(f'"{p}"' in phase["description"] for p in {d["phase"] for d in progress}
               if not any(c.isdigit() for c in p))  # "compare depth N": the depth varies
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
    # Same answer as the store module itself, frame rate included.
    direct = store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], power_budget=1e4)
    assert rich["packed"] == direct.packed and rich["indices"] == list(direct.indices)
    assert store.frame_times_known and rich["fps_target"] == store.fps
    assert (rich["frame_time_s"], rich["fps"], rich["meets_fps"]) == (direct.frame_time_s, direct.fps,
                                                                      direct.meets_fps)
    assert rich["frame_time_s"] > 0 and rich["fps"] <= store.fps
    # which display every figure holds for: the job priced its store at the path's own 64x48
    for answer in (cheap, rich):
        assert answer["figures_resolution"] == [64, 48] and answer["figures_kind"] == "display"
    # the prediction for this camera (interpolated between the frontier's pricing cameras), never above
    # the stored worst figures the budget was checked against
    assert (rich["expected_error"], rich["expected_power_w"]) == (direct.expected_error,
                                                                  direct.expected_power_w)
    assert rich["expected_error"] <= rich["error"] and rich["expected_power_w"] <= rich["power_w"]
    # Another frame rate: the store's lookup at that rate (power repriced, slower settings left out).
    fast = client.post(f"/stores/{job['store_id']}/query",
                       json={**query, "power_budget_w": 1e4, "fps": 2 * store.fps}).json()
    at = store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], power_budget=1e4, fps=2 * store.fps)
    assert fast["fps_target"] == 2 * store.fps and fast["indices"] == list(at.indices)
    assert (fast["power_w"], fast["meets_fps"], fast["fps"]) == (at.power_w, at.meets_fps, at.fps)
    assert client.post(f"/stores/{job['store_id']}/query",
                       json={**query, "power_budget_w": 1.0, "fps": 0}).status_code == 422
    wide = client.post(f"/stores/{job['store_id']}/query",
                       json={**query, "aspect": 3.0, "power_budget_w": 0.5}).json()
    assert wide["packed"] == store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], power_budget=0.5,
                                          aspect=3.0).packed

    by_error = client.post(f"/stores/{job['store_id']}/query", json={**query, "error_budget": 1.0}).json()
    assert by_error["power_w"] <= rich["power_w"]
    outside = client.post(f"/stores/{job['store_id']}/query",
                          json={"position": [100.0, 0.0, 0.0], "direction": [-1, 0, 0], "error_budget": 0.5})
    assert outside.status_code == 200 and outside.json()["clamped"] is True

    # Temporal filter: half-way through the period from the cheap to the rich settings, along the
    # frontier (every point keeps a 1e4 W budget): the point whose predicted error is nearest to the
    # schedule from the cheap to the rich settings' errors over the transition's period, with its
    # predictions.
    prev = {"indices": cheap["indices"], "elapsed_s": 1.0, "period_s": 2.0}
    mid = client.post(f"/stores/{job['store_id']}/query",
                      json={**query, "power_budget_w": 1e4, "previous": prev}).json()
    hit = store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], power_budget=1e4)
    points = {p.indices: p for p in store.budget_points(hit)}
    errors = {k: p.error for k, p in points.items()}
    at_start = blend(cheap["indices"], rich["indices"], 0.0, errors)
    bound = abs(errors[at_start] - errors[tuple(rich["indices"])])
    period = transition_period(2.0, errors[at_start], errors[tuple(rich["indices"])], errors.values())
    progress = 1.0 / period if period > 0 else 1.0  # elapsed 1 s
    expect = blend(cheap["indices"], rich["indices"], progress, errors, None, bound)
    assert mid["indices"] == list(expect) and mid["target_indices"] == rich["indices"]
    assert mid["filtered"] == (list(expect) != rich["indices"])
    assert (mid["power_w"], mid["error"]) == (points[expect].power_w, points[expect].error)
    assert (mid["expected_error"], mid["expected_power_w"]) == store.expected(hit, points[expect])
    late = client.post(f"/stores/{job['store_id']}/query",
                       json={**query, "power_budget_w": 1e4, "previous": {**prev, "elapsed_s": 5.0}}).json()
    assert late["indices"] == rich["indices"] and late["filtered"] is False
    assert (mid["figures_resolution"], mid["figures_kind"]) == ([64, 48], "display")  # filtered answers too
    bad = client.post(f"/stores/{job['store_id']}/query",
                      json={**query, "power_budget_w": 1.0, "previous": {**prev, "indices": [0]}})
    assert bad.status_code == 422


def test_events_can_be_replayed_after_the_end(client: httpx.Client, finished: dict[str, Any]) -> None:
    """A finished job's log keeps its state changes and its last progress event (trimmed at the end)."""
    job = finished["job"]
    live = finished["events"]
    last_progress = max(d["seq"] for k, d in live if k == "progress")
    kept = [(k, d) for k, d in live if k != "progress" or d["seq"] == last_progress]
    again = sse_events(client, f"/jobs/{job['id']}/events")
    assert [(k, d["seq"]) for k, d in again] == [(k, d["seq"]) for k, d in kept]
    assert again[-2][1] == kept[-2][1]  # the last progress, unchanged
    assert [k for k, _ in again].count("progress") == 1
    assert again[-1][1]["seq"] > len(again)  # earlier progress events are gone, numbers unchanged
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
    spec = tiny_job(scene["id"], resolution=(160, 120), depth_values=(0, 1, 2))
    # the paper's view cubes split twice: far more work than this 3-frame path's few path samples, so
    # the job is still running when the cancel arrives
    spec["options"].update(max_depth=2, view_sampling="aimed")
    job = client.post("/jobs", json=spec).json()
    wait_job(client, job["id"], {"running", "done"})
    deadline = time.monotonic() + 60
    while client.get(f"/jobs/{job['id']}").json()["progress"]["evaluations"] == 0:
        assert time.monotonic() < deadline
        time.sleep(0.02)
    assert client.delete(f"/jobs/{job['id']}").status_code == 409  # running: cancel first
    r = client.post(f"/jobs/{job['id']}/cancel")
    assert r.status_code == 200 and r.json()["cancel_requested"] is True
    events = sse_events(client, f"/jobs/{job['id']}/events")
    assert events[-1][0] == "cancelled"
    final = client.get(f"/jobs/{job['id']}").json()
    assert final["state"] == "cancelled" and final["store_id"] is None
    assert client.post(f"/jobs/{job['id']}/cancel").status_code == 200  # idempotent


def test_cancel_of_a_finished_job_is_409(client: httpx.Client, finished: dict[str, Any]) -> None:
    r = client.post(f"/jobs/{finished['job']['id']}/cancel")
    assert r.status_code == 409 and r.json()["error"]["code"] == "conflict"


def test_job_request_errors_name_the_problem(client: httpx.Client, scene: dict[str, Any]) -> None:
    spec = tiny_job(scene["id"])
    for patch, needle in (({"profile": "nonexistent"}, "profile"),
                          ({"space": {"sampling": ["ultra"]}}, "ultra"),
                          ({"space": {"shadow_samples": [3]}}, "3"),
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
    assert best["deadline_met"] and best["fps"] == best["fps_target"] == 30.0
    # power for a bigger frame (the path's, as stores predict it): static stays, dynamic energy and frame
    # time scale by pixels, and the power is drawn at the frame rate the bigger frame reaches
    big = client.post("/evaluate", json={"scene_id": scene["id"], "camera": camera(),
                                         "power_resolution": [320, 240]}).json()
    static_w = best["breakdown"]["energy_j.static"] * 30.0
    dynamic = (best["power_w"] - static_w) / 30.0
    assert big["frame_time_s"] == pytest.approx(100 * best["frame_time_s"], rel=1e-12)
    rate = min(30.0, 1.0 / big["frame_time_s"])
    assert big["fps"] == pytest.approx(rate) and big["deadline_met"] == (big["frame_time_s"] <= 1 / 30)
    assert big["power_w"] == pytest.approx(static_w + 100 * dynamic * rate, rel=1e-9)
    assert big["power_w"] <= static_w + dynamic / best["frame_time_s"] * (1 + 1e-12)  # full-speed power
    assert big["error"] == 0.0 and big["breakdown"]["pixel_ratio"] == 100.0
    r = client.post("/evaluate", json={"scene_id": scene["id"], "camera": camera(),
                                       "settings": {"max_depth": 7}})
    assert r.status_code == 422 and "max_depth" in r.json()["error"]["message"]
    r = client.post("/render", json={"scene_id": "0" * 64, "camera": camera()})
    assert r.status_code == 404


def test_evaluate_renders_each_image_once(client: httpx.Client, scene: dict[str, Any],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """What a path evaluation sends (several settings per camera, two requests in flight, then the same
    settings again under another mode): the requests render at the same time, the camera's reference
    once, maximum quality from that reference, and a repeated request comes from the evaluation cache
    with the same answer. (The server runs in this process, so its renders can be counted.)"""
    from concurrent.futures import ThreadPoolExecutor

    from service import evaluation

    real = evaluation._render
    rendered: list[Any] = []
    in_flight, most = [0], [0]
    lock = threading.Lock()
    both = threading.Barrier(2, timeout=30)

    def counting(scene_: Any, cam: Any, settings: Any, threads: Any) -> Any:
        if (cam.width, cam.height) != (40, 30):  # anything else the server renders meanwhile
            return real(scene_, cam, settings, threads)
        with lock:
            rendered.append(settings)
            in_flight[0] += 1
            most[0] = max(most[0], in_flight[0])
        try:
            if settings.mode != "fsaa":  # the two cheap settings: each waits until the other renders too
                both.wait()
            return real(scene_, cam, settings, threads)
        finally:
            with lock:
                in_flight[0] -= 1

    monkeypatch.setattr(evaluation, "_render", counting)
    cam = camera(40, 30)  # a size no other test evaluates: its reference is not cached yet
    cheap = [{"sampling": "undersample_4x4", "ao_samples": 0}, {"sampling": "1spp", "shadow_samples": 1}]

    def ask(settings: dict[str, Any]) -> dict[str, Any]:
        r = client.post("/evaluate", json={"scene_id": scene["id"], "camera": cam, "settings": settings,
                                           "power_resolution": [320, 240]})
        assert r.status_code == 200, r.text
        return r.json()

    with ThreadPoolExecutor(2) as pool:
        first = list(pool.map(ask, cheap))
    assert most[0] == 2  # both evaluations rendered at once
    assert len(rendered) == 3 and sum(s.mode == "fsaa" for s in rendered) == 1  # one reference
    best = ask({})
    assert best["error"] == 0.0 and len(rendered) == 3  # maximum quality: the reference render, priced
    monkeypatch.setattr(evaluation, "_render", real)  # (a fresh render, to compare with)
    r = client.post("/render", json={"scene_id": scene["id"], "camera": cam, "fps": 30.0})
    pixel_ratio = 320 * 240 / (40 * 30)
    assert r.json()["energy"]["frame_time_s"] * pixel_ratio == pytest.approx(best["frame_time_s"], rel=1e-12)
    monkeypatch.setattr(evaluation, "_render", counting)
    again = [ask(s) for s in cheap]
    assert again == first and len(rendered) == 3  # the evaluation cache answered


def test_query_answers_like_the_store_and_fails_like_every_route(client: httpx.Client,
                                                                  finished: dict[str, Any]) -> None:
    """The one query route (served without FastAPI's parameter solving) gives the lookup's answers and
    the validation errors, statuses and shapes of any other route."""
    from service.api.routes.stores import answer_query
    from service.api.schemas import StoreQuery

    store_id = finished["job"]["store_id"]
    store = ParetoStore.from_json(client.get(f"/stores/{store_id}").text)
    rng = np.random.default_rng(3)
    for _ in range(12):
        q: dict[str, Any] = {"position": rng.uniform(-4, 4, 3).tolist(),
                             "direction": rng.normal(size=3).tolist(), "fov": float(rng.uniform(0.3, 1.2))}
        q["power_budget_w" if rng.random() < 0.5 else "error_budget"] = float(rng.uniform(0.01, 1))
        r = client.post(f"/stores/{store_id}/query", json=q)
        assert r.status_code == 200, r.text
        assert r.json() == answer_query(store, StoreQuery.model_validate(q)).model_dump(mode="json")
    n = len(store.parameters)
    base = {"position": [0, -3, 1.5], "direction": [0, 1, -0.3], "error_budget": 0.1}
    for body, status, field in (
            ({**base, "previous": {"indices": [15] * n, "elapsed_s": 0.7}}, 422, None),
            ({**base, "power_budget_w": 1.0}, 422, None),
            ({"position": "here", "error_budget": 0.1}, 422, "position"),
            ({**base, "direction": [0, 0, 0]}, 422, None)):
        r = client.post(f"/stores/{store_id}/query", json=body)
        assert r.status_code == status, (body, r.text)
        err = r.json()["error"]
        assert err["code"] == "validation_error" and err["message"]
        if field is not None:
            assert any(d["loc"][:2] == ["body", field] for d in err["details"]), err
    valid = b'{"position": [0, 0, 0], "direction": [0, 1, 0], "error_budget": 0.1}'
    for data, ctype in ((b'{"position": [0, NaN, 0], "error_budget": 0.1}', "application/json"),
                        (b'{"position": [0, 0', "application/json"), (b"[]", "application/json"),
                        (valid, "text/plain")):
        r = client.post(f"/stores/{store_id}/query", content=data, headers={"Content-Type": ctype})
        assert r.status_code == 422 and set(r.json()["error"]) == {"status", "code", "message", "details"}
    r = client.post("/stores/" + "f" * 32 + "/query", json=base)
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"
    paths = client.get("/openapi.json").json()["paths"]
    assert paths["/stores/{store_id}/query"]["post"]["requestBody"]["content"]["application/json"]["schema"] \
        == {"$ref": "#/components/schemas/StoreQuery"}


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


def test_an_idle_event_stream_sends_keepalives_and_ends_cleanly(tmp_path: Path) -> None:
    """A queued job's stream stays open with comment lines until the job ends (here: cancelled)."""
    with server_thread(Settings(data_dir=tmp_path, job_workers=1, sse_keepalive_s=0.2)) as url, \
            httpx.Client(base_url=url, timeout=60) as c:
        scene = c.post("/scenes", content=teapot_scene_glb(), headers=GLB).json()["id"]
        # busy for far longer than the two keepalives take (it is cancelled then): a job that ended first
        # would let the waiting one run and finish instead of being cancelled while queued
        busy = tiny_job(scene, resolution=(192, 144), depth_values=(0, 1, 2))
        busy["options"].update(max_depth=2, view_sampling="aimed")
        first = c.post("/jobs", json=busy).json()
        waiting = c.post("/jobs", json=tiny_job(scene)).json()  # queued behind the first
        lines: list[str] = []
        with c.stream("GET", f"/jobs/{waiting['id']}/events") as r:
            assert r.headers["content-type"].startswith("text/event-stream")
            for line in r.iter_lines():
                lines.append(line)
                if lines.count(": keepalive") == 2:
                    for job in (waiting, first):
                        assert c.post(f"/jobs/{job['id']}/cancel").status_code == 200
        assert lines[:2] == ["id: 1", "event: queued"]
        assert "event: running" not in lines, "the busy job ended before the keepalives: make it longer"
        assert "event: cancelled" in lines and lines.count(": keepalive") >= 2  # and then the stream ended


def test_verify_a_store_over_rest(client: httpx.Client, finished: dict[str, Any],
                                  scene: dict[str, Any]) -> None:
    """POST /stores/{id}/verify renders sampled path frames with the store's settings; its measured power
    is what POST /evaluate gives for the same frame and settings (errors: tests/test_verify.py)."""
    job = finished["job"]
    path = camera_path(3)
    r = client.post(f"/stores/{job['store_id']}/verify",
                    json={"camera_path": path, "error_budget": 0.05, "frames": 2})
    assert r.status_code == 200, r.text
    doc = r.json()
    assert doc["budget_mode"] == "error" and doc["resolution"] == [64, 48] and len(doc["frames"]) == 2
    assert doc["store_figures_resolution"] == [64, 48]  # the job's store was priced at the path's size
    assert doc["store_figures_kind"] == "display"
    store = ParetoStore.from_json(client.get(f"/stores/{job['store_id']}").text)
    best = store.settings_of([p.max_quality for p in store.parameters])
    for f in doc["frames"]:
        frame = path["frames"][f["frame"]]
        cam = {"matrix_world": frame["matrix_world"], "vfov": frame["vfov"], "width": 64, "height": 48}
        ev = client.post("/evaluate", json={"scene_id": scene["id"], "camera": cam,
                                            "settings": f["settings"]})
        assert ev.status_code == 200
        assert f["measured_power_w"] == pytest.approx(ev.json()["power_w"], rel=1e-9)
        if f["settings"] == best:
            assert f["measured_error"] == 0.0
        assert f["within_budget"] == (f["measured_error"] <= 0.05)
    assert doc["summary"]["frames"] == 2
    both = client.post(f"/stores/{job['store_id']}/verify",
                       json={"camera_path": path, "error_budget": 0.05, "power_budget_w": 1.0})
    assert both.status_code == 422
    missing = client.post("/stores/nope/verify", json={"camera_path": path, "error_budget": 0.05})
    assert missing.status_code == 404


def test_a_job_searches_values_between_the_default_steps(client: httpx.Client,
                                                          scene: dict[str, Any]) -> None:
    """A job's ``space`` may name renderable values the default search space lacks (2 shadow rays, AO 10):
    its store names them, POST /evaluate renders them, and verify prices its picks like /evaluate."""
    spec = tiny_job(scene["id"])
    spec["space"] = {**spec["space"], "shadow_samples": [1, 2], "ao_samples": [0, 10]}
    spec["parameters"] = ["shadow_samples", "ao_samples"]
    r = client.post("/jobs", json=spec)
    assert r.status_code == 201, r.text
    events = sse_events(client, f"/jobs/{r.json()['id']}/events")
    assert events[-1][0] == "done", events[-1]
    job = client.get(f"/jobs/{r.json()['id']}").json()
    store = ParetoStore.from_json(client.get(f"/stores/{job['store_id']}").text)
    values = {p.name: list(p.values) for p in store.parameters}
    assert values["shadow_samples"] == [1, 2] and values["ao_samples"] == [0, 10]
    path = camera_path(3)
    doc = client.post(f"/stores/{job['store_id']}/verify",
                      json={"camera_path": path, "error_budget": 0.05, "frames": 3}).json()
    for f in doc["frames"]:
        frame = path["frames"][f["frame"]]
        cam = {"matrix_world": frame["matrix_world"], "vfov": frame["vfov"], "width": 64, "height": 48}
        ev = client.post("/evaluate", json={"scene_id": scene["id"], "camera": cam,
                                            "settings": f["settings"]})
        assert ev.status_code == 200, ev.text
        assert f["measured_power_w"] == pytest.approx(ev.json()["power_w"], rel=1e-9)
    between = {"shadow_samples": 2, "ao_samples": 10}
    ev = client.post("/evaluate", json={"scene_id": scene["id"], "camera": camera(), "settings": between})
    top = client.post("/evaluate", json={"scene_id": scene["id"], "camera": camera(),
                                         "settings": {"shadow_samples": 16, "ao_samples": 16}})
    assert ev.status_code == 200 and top.status_code == 200
    assert 0 < ev.json()["error"] and top.json()["error"] == 0.0
    assert ev.json()["power_w"] < top.json()["power_w"]


def test_query_and_verify_take_the_lookup_priority(client: httpx.Client, finished: dict[str, Any]) -> None:
    """POST /stores/{id}/query and /verify: ``priority`` reaches the store's lookup (the answer is the
    store's own under it, and echoes it), an older request without the field is answered as before
    (frame rate first), and a bad value is a 422 naming the field."""
    job = finished["job"]
    store = ParetoStore.from_json(client.get(f"/stores/{job['store_id']}").text)
    frame = camera_path(3)["frames"][1]
    m = np.asarray(frame["matrix_world"])
    query = {"position": m[:3, 3].tolist(), "matrix": frame["matrix_world"], "fov": frame["vfov"],
             "error_budget": 0.0}
    url = f"/stores/{job['store_id']}/query"
    old = client.post(url, json=query).json()
    assert old["priority"] == "frame_rate"
    before = store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], error_budget=0.0)
    assert old["indices"] == list(before.indices)
    for priority, fps in (("frame_rate", None), ("budget", None), ("budget", 4 * store.fps)):
        body = {**query, "priority": priority, **({} if fps is None else {"fps": fps})}
        got = client.post(url, json=body).json()
        hit = store.lookup(m[:3, 3], matrix=m, fov=frame["vfov"], error_budget=0.0, fps=fps,
                           priority=priority)
        assert got["priority"] == hit.priority == priority
        assert (got["indices"], got["power_w"], got["meets_fps"], got["fps_target"]) == (
            list(hit.indices), hit.power_w, hit.meets_fps, hit.fps_target)
    # through the temporal filter too (the previous settings a frame later)
    filtered = client.post(url, json={**query, "priority": "budget", "previous": {
        "indices": old["indices"], "elapsed_s": 0.5}}).json()
    assert filtered["priority"] == "budget"
    for bad in ("speed", "", 1, None):
        r = client.post(url, json={**query, "priority": bad})
        assert r.status_code == 422 and "priority" in r.text, (bad, r.text)
    path = camera_path(3)
    v = client.post(f"/stores/{job['store_id']}/verify", json={
        "camera_path": path, "error_budget": 0.05, "frames": 1, "resolution": [32, 24], "priority": "budget",
        "fps": 2 * store.fps})
    assert v.status_code == 200, v.text
    doc = v.json()
    assert (doc["priority"], doc["fps"]) == ("budget", 2 * store.fps)
    f = doc["frames"][0]
    pf = path["frames"][f["frame"]]
    pm = np.asarray(pf["matrix_world"])
    hit = store.lookup(pm[:3, 3], matrix=pm, fov=pf["vfov"], aspect=pf["resolution"][0] / pf["resolution"][1],
                       error_budget=0.05, fps=2 * store.fps, priority="budget")
    assert f["settings"] == hit.settings and f["meets_fps"] == hit.meets_fps
    bad = client.post(f"/stores/{job['store_id']}/verify", json={"camera_path": path, "error_budget": 0.05,
                                                                  "priority": "speed"})
    assert bad.status_code == 422 and "priority" in bad.text


def _store_and_a_frame(client: httpx.Client, job: dict[str, Any]) -> tuple:
    """A finished job's store, a 3-frame path, its middle frame's camera as lookup keywords and as the
    start of a REST query (without a budget)."""
    store = ParetoStore.from_json(client.get(f"/stores/{job['store_id']}").text)
    path = camera_path(3)
    frame = path["frames"][1]
    m = np.asarray(frame["matrix_world"])
    look = {"matrix": m, "fov": frame["vfov"], "aspect": frame["resolution"][0] / frame["resolution"][1]}
    query = {"position": m[:3, 3].tolist(), "matrix": frame["matrix_world"], "fov": frame["vfov"],
             "aspect": look["aspect"]}
    return store, path, m, look, query


def _verify_one_frame(client: httpx.Client, job: dict[str, Any], store: ParetoStore, path: dict[str, Any],
                      budget: dict[str, float], margin: dict[str, float]) -> tuple:
    """POST /stores/{id}/verify for one frame at 32x24 under ``budget`` (its REST field) and ``margin``:
    the answer, its frame, and the store's own lookup at that frame under the same budget and margin."""
    v = client.post(f"/stores/{job['store_id']}/verify", json={
        "camera_path": path, "frames": 1, "resolution": [32, 24], **budget, **margin})
    assert v.status_code == 200, v.text
    doc = v.json()
    f = doc["frames"][0]
    pf = path["frames"][f["frame"]]
    pm = np.asarray(pf["matrix_world"])
    keywords = {"power_budget" if k == "power_budget_w" else k: value for k, value in budget.items()}
    aspect = pf["resolution"][0] / pf["resolution"][1]
    want = store.lookup(pm[:3, 3], matrix=pm, fov=pf["vfov"], aspect=aspect, **keywords, **margin)
    return doc, f, want


def test_query_and_verify_take_an_error_margin(client: httpx.Client, finished: dict[str, Any]) -> None:
    """POST /stores/{id}/query and /verify: ``error_margin`` searches the error budget that much lower (the
    store's own answer under it, echoed), verify still judges the frames against the budget itself, and
    a margin out of bounds is a 422 naming the field."""
    job = finished["job"]
    store, path, m, look, query = _store_and_a_frame(client, job)
    plain = store.lookup(m[:3, 3], **look, error_budget=0.05)
    assert plain.error > 0  # searched under half its error, the answer must change
    margin = 0.05 - plain.error / 2
    query["error_budget"] = 0.05
    url = f"/stores/{job['store_id']}/query"
    got = client.post(url, json={**query, "error_margin": margin}).json()
    hit = store.lookup(m[:3, 3], **look, error_budget=0.05, error_margin=margin)
    lowered = store.lookup(m[:3, 3], **look, error_budget=0.05 - margin)
    assert got["error_margin"] == margin and (got["indices"], got["infeasible"]) == (
        list(hit.indices), hit.infeasible) == (list(lowered.indices), lowered.infeasible)
    assert (list(plain.indices), plain.infeasible) != (got["indices"], got["infeasible"])
    assert client.post(url, json=query).json()["error_margin"] == 0.0
    for bad in (-0.01, 0.9, "x"):
        r = client.post(url, json={**query, "error_margin": bad})
        assert r.status_code == 422 and "error_margin" in r.text, (bad, r.text)
    doc, f, want = _verify_one_frame(client, job, store, path, {"error_budget": 0.05},
                                     {"error_margin": margin})
    assert doc["error_margin"] == margin and f["settings"] == want.settings
    assert f["within_budget"] == (f["measured_error"] <= 0.05)  # judged against the budget itself


def test_query_and_verify_take_a_power_margin(client: httpx.Client, finished: dict[str, Any]) -> None:
    """POST /stores/{id}/query and /verify: ``power_margin`` searches a power budget that share lower (the
    store's own answer under it, echoed), verify still judges the frames against the budget itself, and
    a margin out of bounds is a 422 naming the field."""
    job = finished["job"]
    store, path, m, look, query = _store_and_a_frame(client, job)
    best = store.lookup(m[:3, 3], **look, error_budget=0.0)  # the most accurate setting ...
    watts = best.power_w * 1.001  # ... just keeps this budget: 20 % under it, it does not
    plain = store.lookup(m[:3, 3], **look, power_budget=watts)
    assert plain.indices == best.indices
    query["power_budget_w"] = watts
    url = f"/stores/{job['store_id']}/query"
    got = client.post(url, json={**query, "power_margin": 0.2}).json()
    lowered = store.lookup(m[:3, 3], **look, power_budget=watts * 0.8)
    assert got["power_margin"] == 0.2 and got["error_margin"] == 0.0
    assert (got["indices"], got["infeasible"]) == (list(lowered.indices), lowered.infeasible)
    assert got["indices"] != list(plain.indices)
    assert client.post(url, json=query).json()["power_margin"] == 0.0
    for bad in (-0.01, 0.6, "x"):
        r = client.post(url, json={**query, "power_margin": bad})
        assert r.status_code == 422 and "power_margin" in r.text, (bad, r.text)
    doc, f, want = _verify_one_frame(client, job, store, path, {"power_budget_w": watts},
                                     {"power_margin": 0.2})
    assert doc["power_margin"] == 0.2 and doc["error_margin"] == 0.0 and f["settings"] == want.settings
    assert f["within_budget"] == (f["measured_power_w"] <= watts)  # judged against the budget itself
