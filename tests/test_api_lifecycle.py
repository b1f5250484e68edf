"""Data lifecycle on a real server: scenes, jobs and stores are listed a page at a time and deleted,
never while something still needs them; the evaluation cache stays under its cap without evicting what
a running job uses."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from api_support import (
    box,
    box_scene_glb,
    glb_bytes,
    plane,
    server_thread,
    sse_events,
    teapot_scene_glb,
    tiny_job,
)

from service.api import Settings

pytestmark = pytest.mark.service

GLB = {"Content-Type": "model/gltf-binary"}


@pytest.fixture
def client(tmp_path: Path) -> Iterator[httpx.Client]:
    with server_thread(Settings(data_dir=tmp_path, job_workers=1)) as url, \
            httpx.Client(base_url=url, timeout=120) as c:
        yield c


def run_job(client: httpx.Client, spec: dict[str, Any]) -> dict[str, Any]:
    job = client.post("/jobs", json=spec)
    assert job.status_code == 201, job.text
    assert sse_events(client, f"/jobs/{job.json()['id']}/events")[-1][0] == "done"
    return client.get(f"/jobs/{job.json()['id']}").json()


def all_pages(client: httpx.Client, path: str, limit: int) -> list[dict[str, Any]]:
    items, cursor = [], None
    while True:
        params: dict[str, Any] = {"limit": limit, **({"cursor": cursor} if cursor else {})}
        page = client.get(path, params=params)
        assert page.status_code == 200, page.text
        body = page.json()
        assert len(body["items"]) <= limit
        items += body["items"]
        if body["next_cursor"] is None:
            return items
        cursor = body["next_cursor"]


def test_listings_page_through_everything_newest_first(client: httpx.Client) -> None:
    ids = []
    for k in range(5):
        r = client.post("/scenes", content=glb_bytes([box(half=0.2 + 0.1 * k), plane()]), headers=GLB)
        ids.append(r.json()["id"])
    scenes = all_pages(client, "/scenes", 2)
    assert [s["id"] for s in scenes] == ids[::-1]
    assert scenes[0] == client.get(f"/scenes/{ids[-1]}").json()
    job = run_job(client, tiny_job(ids[0]))
    assert [j["id"] for j in all_pages(client, "/jobs", 1)] == [job["id"]]
    assert client.get("/jobs", params={"state": "done"}).json()["items"][0]["id"] == job["id"]
    assert client.get("/jobs", params={"state": "running"}).json()["items"] == []
    assert client.get("/jobs", params={"scene_id": ids[1]}).json()["items"] == []
    stores = client.get("/stores").json()
    assert [s["id"] for s in stores["items"]] == [job["store_id"]] and stores["next_cursor"] is None
    assert stores["items"][0]["size"] == len(client.get(f"/stores/{job['store_id']}").content)
    for bad in ({"cursor": "not-a-cursor"}, {"limit": 0}, {"limit": 5000}, {"state": "sleeping"}):
        r = client.get("/jobs", params=bad)
        assert r.status_code == 422 and r.json()["error"]["code"] == "validation_error", (bad, r.text)


def test_a_scene_is_deleted_only_when_no_job_needs_it(client: httpx.Client, tmp_path: Path) -> None:
    scene = client.post("/scenes", content=teapot_scene_glb(), headers=GLB).json()["id"]
    spec = tiny_job(scene, resolution=(96, 72), depth_values=(0, 1, 2))
    spec["options"].update(max_depth=1, view_sampling="aimed")  # a few seconds of work
    job = client.post("/jobs", json=spec).json()
    r = client.delete(f"/scenes/{scene}")
    assert r.status_code == 409 and "cancel them first" in r.json()["error"]["message"]
    assert client.delete(f"/jobs/{job['id']}").status_code == 409  # queued or running: cancel first
    assert client.post(f"/jobs/{job['id']}/cancel").status_code == 200
    assert sse_events(client, f"/jobs/{job['id']}/events")[-1][0] == "cancelled"
    done = run_job(client, tiny_job(scene))
    assert client.delete(f"/jobs/{job['id']}").status_code == 204
    assert client.get(f"/jobs/{job['id']}").status_code == 404
    assert client.delete(f"/jobs/{job['id']}").status_code == 404

    assert client.delete(f"/scenes/{scene}").status_code == 204
    assert client.get(f"/scenes/{scene}").status_code == 404
    assert not (tmp_path / "scenes" / f"{scene}.glb").exists()
    assert client.get(f"/jobs/{done['id']}").status_code == 404  # its finished jobs went with it ...
    store = client.get(f"/stores/{done['store_id']}")  # ... its results did not
    assert store.status_code == 200
    query = {"position": [0, -3, 1.5], "direction": [0, 1, -0.3], "error_budget": 0.05}
    assert client.post(f"/stores/{done['store_id']}/query", json=query).status_code == 200
    for route in ("/render", "/evaluate"):
        r = client.post(route, json={"scene_id": scene, "camera": {
            "matrix_world": [[1, 0, 0, 0], [0, 0, -1, -3], [0, 1, 0, 1], [0, 0, 0, 1]], "vfov": 0.7,
            "width": 16, "height": 12}})
        assert r.status_code == 404, r.text
    assert client.post("/jobs", json=tiny_job(scene)).status_code == 404
    assert client.delete(f"/scenes/{scene}").status_code == 404

    assert client.delete(f"/stores/{done['store_id']}").status_code == 204
    assert client.get(f"/stores/{done['store_id']}").status_code == 404
    assert client.post(f"/stores/{done['store_id']}/query", json=query).status_code == 404
    assert client.delete(f"/stores/{done['store_id']}").status_code == 404


def evaluations_by_scene(data_dir: Path) -> dict[str, int]:
    db = sqlite3.connect(f"file:{data_dir / 'eval_cache.sqlite3'}?mode=ro", uri=True)
    try:
        return dict(db.execute("SELECT scene, COUNT(*) FROM evaluations GROUP BY scene").fetchall())
    finally:
        db.close()


def comparable(store: str) -> str:
    doc = json.loads(store)
    for key in ("evaluations", "cache_hits", "elapsed_s", "executor"):
        doc["meta"].pop(key)
    return json.dumps(doc, sort_keys=True)


def test_the_evaluation_cache_stays_under_its_cap_and_keeps_what_a_job_uses(tmp_path: Path) -> None:
    """With a cap far below two jobs' evaluations: a running job's own evaluations all stay (they are
    counted right after it finished), an older scene's make room, and no store changes."""
    capped, free = tmp_path / "capped", tmp_path / "free"
    scenes = {"teapot": teapot_scene_glb(), "box": box_scene_glb()}
    specs, hashes, counts, stores = {}, {}, {}, {}
    with server_thread(Settings(data_dir=capped, job_workers=1, eval_cache_max_bytes=64 * 1024)) as url, \
            httpx.Client(base_url=url, timeout=120) as c:
        for name, glb in scenes.items():
            scene = c.post("/scenes", content=glb, headers=GLB).json()
            hashes[name] = scene["content_hash"]
            specs[name] = tiny_job(scene["id"], resolution=(24, 18), depth_values=(0, 1, 2))
            specs[name]["options"].update(max_depth=1, view_sampling="aimed")
            job = run_job(c, specs[name])
            counts[name] = job["progress"]["evaluations"]
            assert evaluations_by_scene(capped)[hashes[name]] == counts[name] > 0
            stores[name] = c.get(f"/stores/{job['store_id']}").text
        assert evaluations_by_scene(capped).get(hashes["teapot"], 0) < counts["teapot"]  # made room
        rerun = run_job(c, specs["teapot"])
        assert rerun["progress"]["evaluations"] > 0  # what was evicted is rendered again ...
        assert comparable(c.get(f"/stores/{rerun['store_id']}").text) == comparable(stores["teapot"])
    # ... and eviction changed no result: the same jobs without a cap give the same stores.
    with server_thread(Settings(data_dir=free, job_workers=1)) as url, \
            httpx.Client(base_url=url, timeout=120) as c:
        for name, glb in scenes.items():
            c.post("/scenes", content=glb, headers=GLB)
            job = run_job(c, specs[name])
            assert comparable(c.get(f"/stores/{job['store_id']}").text) == comparable(stores[name])
