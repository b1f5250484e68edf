"""REST edges on a real uvicorn server: the bad-input table, the error shape, tokens and binds."""

from __future__ import annotations

import json
import struct
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
from api_support import ServerProcess, box, box_scene_glb, camera_path, glb_bytes, plane, server_thread

from service.api import Settings

pytestmark = pytest.mark.service

GLB = {"Content-Type": "model/gltf-binary"}
POSE = {"position": [0, 0, 0], "direction": [0, 1, 0]}


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("api-edges")


@pytest.fixture(scope="module")
def base(data_dir: Path) -> Iterator[str]:
    with server_thread(Settings(data_dir=data_dir, max_upload_bytes=256 * 1024, max_body_bytes=64 * 1024,
                                job_workers=1)) as url:
        yield url


@pytest.fixture(scope="module")
def client(base: str) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=base, timeout=60.0) as c:
        yield c


def assert_error(r: httpx.Response, status: int, *needles: str) -> dict:
    assert r.status_code == status, r.text
    body = r.json()
    assert set(body) == {"error"}
    err = body["error"]
    assert set(err) == {"status", "code", "message", "details"}
    assert err["status"] == status and isinstance(err["code"], str) and err["message"]
    for needle in needles:
        assert needle.lower() in err["message"].lower(), err["message"]
    return err


def test_health_reports_version_and_executor(client: httpx.Client) -> None:
    r = client.get("/health")
    assert r.status_code == 200
    body = r.json()
    assert body["status"] == "ok" and body["version"] == "0.1.0"
    assert body["executor"] == "in-process"
    assert set(body["jobs"]) == {"queued", "running", "done", "failed", "cancelled"}


def test_data_dir_uses_wal(data_dir: Path, client: httpx.Client) -> None:
    from service.storage import Storage

    s = Storage(data_dir)
    try:
        assert s.journal_mode() == "wal"
    finally:
        s.close()


def test_second_service_on_the_same_data_dir_refuses(data_dir: Path, client: httpx.Client) -> None:
    srv = ServerProcess(data_dir)
    assert srv.proc.wait(60) != 0
    assert "in use by another render-budget service" in srv.output()
    assert client.get("/health").status_code == 200  # the first one is unaffected


def test_openapi_documents_every_endpoint(client: httpx.Client) -> None:
    paths = client.get("/openapi.json").json()["paths"]
    assert {"/scenes", "/scenes/{scene_id}", "/jobs", "/jobs/{job_id}", "/jobs/{job_id}/events",
            "/stores/{store_id}", "/stores/{store_id}/query", "/render", "/evaluate", "/health"} <= set(paths)
    assert client.get("/docs").status_code == 200


# -- uploads ------------------------------------------------------------------------------------------
def test_oversize_upload_is_413(client: httpx.Client, data_dir: Path) -> None:
    r = client.post("/scenes", content=b"glTF" + b"\0" * (300 * 1024), headers=GLB)
    assert_error(r, 413, "limit")
    assert list((data_dir / "tmp").iterdir()) == []


def test_oversize_streamed_upload_without_length_is_413(client: httpx.Client) -> None:
    def chunks() -> Iterator[bytes]:
        for _ in range(40):
            yield b"\0" * 8192

    r = client.post("/scenes", content=chunks(), headers=GLB)
    assert_error(r, 413, "limit")


def test_not_a_gltf_is_400(client: httpx.Client) -> None:
    r = client.post("/scenes", content=b"solid cube\nfacet normal 0 0 1\n" * 4, headers=GLB)
    assert_error(r, 400, "magic")


def test_truncated_glb_is_400(client: httpx.Client) -> None:
    data = box_scene_glb()
    r = client.post("/scenes", content=data[: len(data) // 2], headers=GLB)
    assert_error(r, 400, "truncated")


def test_glb_with_broken_json_chunk_is_rejected(client: httpx.Client) -> None:
    payload = b'{"asset": {"version": "2.0"'  # cut JSON
    payload += b" " * (-len(payload) % 4)
    data = struct.pack("<4sII", b"glTF", 2, 20 + len(payload)) + struct.pack("<I4s", len(payload), b"JSON")
    r = client.post("/scenes", content=data + payload, headers=GLB)
    err = assert_error(r, r.status_code if r.status_code in (400, 422) else 400, "json")
    # the server's file names stay private
    assert "tmp" not in err["message"] and "upload.glb" in err["message"]


def test_nan_geometry_is_422(client: httpx.Client) -> None:
    bad = box()
    pos = np.asarray(bad["positions"])
    pos[3, 1] = np.nan
    bad["positions"] = pos.tolist()
    r = client.post("/scenes", content=glb_bytes([bad, plane()]), headers=GLB)
    assert_error(r, 422, "nan")


def test_empty_upload_is_400(client: httpx.Client) -> None:
    assert_error(client.post("/scenes", content=b"", headers=GLB), 400)


def test_upload_needs_binary_content_type(client: httpx.Client) -> None:
    assert_error(client.post("/scenes", json={"a": 1}), 415, "model/gltf-binary")


# -- unknown ids ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("method,path", [
    ("GET", "/scenes/" + "0" * 64), ("GET", "/scenes/../../etc/passwd"), ("GET", "/jobs/nope"),
    ("DELETE", "/jobs/nope"), ("GET", "/jobs/nope/events"), ("GET", "/stores/nope"),
])
def test_unknown_ids_are_404(client: httpx.Client, method: str, path: str) -> None:
    assert_error(client.request(method, path), 404)


def test_query_of_unknown_store_is_404(client: httpx.Client) -> None:
    r = client.post("/stores/" + "f" * 32 + "/query", json={**POSE, "error_budget": 0.1})
    assert_error(r, 404, "not found")


def test_job_for_unknown_scene_is_404(client: httpx.Client) -> None:
    r = client.post("/jobs", json={"scene_id": "a" * 64, "camera_path": camera_path()})
    assert_error(r, 404, "scene")


# -- malformed bodies ------------------------------------------------------------------------------------
def test_malformed_json_is_422(client: httpx.Client) -> None:
    r = client.post("/jobs", content=b'{"scene_id": "abc", ', headers={"Content-Type": "application/json"})
    assert_error(r, 422, "json")


def test_wrong_types_are_422(client: httpx.Client) -> None:
    path = camera_path()
    path["frames"][0]["vfov"] = "wide"
    err = assert_error(client.post("/jobs", json={"scene_id": "a" * 64, "camera_path": path}), 422, "vfov")
    assert any("vfov" in d["loc"] for d in err["details"])


def test_booleans_and_texts_are_not_numbers(client: httpx.Client) -> None:
    """Found by the fuzzer: a lax parser read ``false`` as 0.0 where the schema says number."""
    for position in ([0, 0, False], [0, 0, "1"]):
        r = client.post("/stores/" + "f" * 32 + "/query",
                        json={"position": position, "direction": [0, 1, 0], "error_budget": 0.1})
        assert_error(r, 422, "position")
    body = {"scene_id": "a" * 64, "camera_path": camera_path(), "resolution": [True, 32]}
    assert_error(client.post("/jobs", json=body), 422, "resolution")


def test_non_finite_numbers_are_422(client: httpx.Client) -> None:
    # Python's json accepts NaN/Infinity literals; the schemas must not.
    body = b'{"position": [0, NaN, 0], "error_budget": 0.1}'
    r = client.post("/stores/" + "f" * 32 + "/query", content=body,
                    headers={"Content-Type": "application/json"})
    assert_error(r, 422, "position")
    body = b'{"scene_id": "' + b"a" * 64 + b'", "camera_path": {"version": 1, "fps": Infinity, "frames": []}}'
    assert_error(client.post("/jobs", content=body, headers={"Content-Type": "application/json"}), 422, "fps")


@pytest.mark.parametrize("budget", [
    {"power_budget_w": -1.0}, {"power_budget_w": 1e9}, {"power_budget_w": 0.0}, {"error_budget": 1.5},
    {"error_budget": -0.01},
    {"power_budget_w": 1.0, "error_budget": 0.1}, {},
])
def test_out_of_range_budgets_are_422(client: httpx.Client, budget: dict) -> None:
    r = client.post("/stores/" + "f" * 32 + "/query", json={**POSE, **budget})
    assert_error(r, 422)


def test_unknown_fields_are_422(client: httpx.Client) -> None:
    r = client.post("/stores/" + "f" * 32 + "/query",
                    json={"position": [0, 0, 0], "direction": [0, 1, 0], "error_budget": 0.1,
                          "profile": "../../etc/passwd"})
    assert_error(r, 422, "extra")


def test_oversize_json_body_is_413(client: httpx.Client) -> None:
    path = camera_path(n=1)
    path["frames"] = path["frames"] * 2000
    assert_error(client.post("/jobs", json={"scene_id": "a" * 64, "camera_path": path}), 413)


def test_unknown_route_and_method_keep_the_shape(client: httpx.Client) -> None:
    assert_error(client.get("/nowhere"), 404)
    assert_error(client.put("/health"), 405)


# -- tokens and binds --------------------------------------------------------------------------------------
def test_token_guards_every_route_but_health(tmp_path: Path) -> None:
    token = "s3cret-token-for-tests"
    with server_thread(Settings(data_dir=tmp_path, token=token)) as url, httpx.Client(base_url=url) as c:
        assert c.get("/health").status_code == 200
        for path in ("/jobs/x", "/docs", "/openapi.json", "/scenes/" + "0" * 64):
            assert_error(c.get(path), 401, "missing")
            assert_error(c.get(path, headers={"Authorization": "Bearer wrong-token"}), 401, "invalid")
        r = c.get("/scenes/" + "0" * 64, headers={"Authorization": f"Bearer {token}"})
        assert_error(r, 404)
        assert r.status_code == 404
        assert c.get("/openapi.json", headers={"Authorization": f"Bearer {token}"}).status_code == 200
        query = {"position": [0, 0, 0], "direction": [0, 1, 0], "error_budget": 0.1}
        assert_error(c.post("/stores/" + "f" * 32 + "/query", json=query), 401)
        r = c.post("/stores/" + "f" * 32 + "/query", json=query, headers={"Authorization": f"Bearer {token}"})
        assert_error(r, 404)
        # An unauthenticated upload is refused before the body is read.
        assert_error(c.post("/scenes", content=box_scene_glb(), headers=GLB), 401)


def test_non_loopback_bind_refuses_without_token(tmp_path: Path) -> None:
    srv = ServerProcess(tmp_path, host="0.0.0.0")
    assert srv.proc.wait(60) == 2
    assert "refusing to bind" in srv.output()
    with pytest.raises(ValueError, match="token"):
        Settings(host="192.168.1.10").check_bind()
    Settings(host="::1").check_bind()
    Settings(host="localhost").check_bind()


def test_non_loopback_bind_with_token_requires_bearer(tmp_path: Path) -> None:
    token = "off-loopback-token"
    srv = ServerProcess(tmp_path, host="0.0.0.0", token=token).wait_healthy()
    try:
        assert_error(httpx.get(f"{srv.base_url}/jobs/x"), 401)
        r = httpx.get(f"{srv.base_url}/jobs/x", headers={"Authorization": f"Bearer {token}"})
        assert_error(r, 404)
    finally:
        srv.stop()


@pytest.mark.parametrize("options", [
    {"view_sampling": "random"}, {"min_depth": 3, "max_depth": 2}, {"path_resolution": 0.0},
    {"path_resolution": float("inf")}, {"guard_frames": 9}, {"max_depth": 9},
])
def test_bad_optimiser_options_are_422(client: httpx.Client, options: dict) -> None:
    body = {"scene_id": "a" * 64, "camera_path": camera_path(), "options": options}
    r = client.post("/jobs", content=json.dumps(body, allow_nan=True),
                    headers={"Content-Type": "application/json"})
    assert_error(r, 422, "min_depth" if "min_depth" in options else next(iter(options)))
