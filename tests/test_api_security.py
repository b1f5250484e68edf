"""Security regressions on a real server, one per finding: an uploaded glTF cannot make the server read a
file, DNS rebinding is refused on loopback, settings from the environment take effect, a stalled body
is cut off, an oversized query body is a 413, the renderer's camera limits are the schema's, and 405s
name every method of a path."""

from __future__ import annotations

import base64
import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from api_support import (
    REPO_ROOT,
    box_scene_glb,
    camera_path,
    free_port,
    look_at_matrix,
    server_thread,
    wait_healthy,
)

from service.api import Settings
from service.store.camera import VFOV_MAX, VFOV_MIN

pytestmark = pytest.mark.service

GLB = {"Content-Type": "model/gltf-binary"}


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("api-security")


@pytest.fixture(scope="module")
def base(data_dir: Path) -> Iterator[str]:
    with server_thread(Settings(data_dir=data_dir, max_body_bytes=64 * 1024, body_read_timeout_s=1.0,
                                job_workers=1)) as url:
        yield url


@pytest.fixture(scope="module")
def client(base: str) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=base, timeout=60.0) as c:
        yield c


# -- arbitrary file read through an uploaded glTF ---------------------------------------------------------
def _glb(gltf: dict[str, Any], blob: bytes) -> bytes:
    js = json.dumps(gltf).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = len(js).to_bytes(4, "little") + b"JSON" + js + len(blob).to_bytes(4, "little") + b"BIN\0" + blob
    return b"glTF" + (2).to_bytes(4, "little") + (12 + len(body)).to_bytes(4, "little") + body


def hostile_upload(reference: str, where: str) -> bytes:
    """A one-triangle .glb whose second buffer (buffer), texture (image) or environment map names
    ``reference``: the 636-byte attack of the issue, in three places."""
    tri = b"".join(v.to_bytes(4, "little") for v in (0, 0, 0, 0x3F800000, 0, 0, 0, 0x3F800000, 0))
    gltf: dict[str, Any] = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36}],
    }
    if where == "buffer":
        gltf["buffers"].append({"byteLength": 4, "uri": reference})
        gltf["bufferViews"].append({"buffer": 1, "byteOffset": 0, "byteLength": 4})
        gltf["accessors"].append({"bufferView": 1, "componentType": 5125, "count": 1, "type": "SCALAR"})
    elif where == "image":
        gltf.update(images=[{"uri": reference}], textures=[{"source": 0}],
                    materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}])
        gltf["meshes"][0]["primitives"][0]["material"] = 0
    else:
        gltf["scenes"][0]["extras"] = {"render_budget_environment": reference}
    return _glb(gltf, tri)


@pytest.mark.parametrize("where", ["buffer", "image", "environment"])
@pytest.mark.parametrize("kind", ["absolute", "dot-dot", "url-encoded", "symlink", "file-url", "big-file"])
def test_uploaded_gltf_reads_nothing_but_itself(client: httpx.Client, data_dir: Path, tmp_path: Path,
                                               opened_files: list[str], where: str, kind: str) -> None:
    secret = tmp_path / "secret.bin"
    secret.write_bytes(b"\x01\x02\x03\x04" * 16)
    big = tmp_path / "big.bin"
    with open(big, "wb") as f:
        f.truncate(400 * 1024 * 1024)  # sparse: the upload limit must not be bypassed through it
    (data_dir / "tmp" / "secret-link.bin").symlink_to(secret)
    reference = {"absolute": str(secret), "dot-dot": "../service.sqlite3",
                 "url-encoded": "%2e%2e%2fservice.lock", "symlink": "secret-link.bin",
                 "file-url": f"file://{secret}", "big-file": str(big)}[kind]
    scenes_before = client.get("/scenes").json()["items"]
    opened_files.clear()
    try:
        r = client.post("/scenes", content=hostile_upload(reference, where), headers=GLB)
    finally:
        (data_dir / "tmp" / "secret-link.bin").unlink()
    assert r.status_code == 422, r.text
    message = r.json()["error"]["message"]
    assert "self-contained" in message and "upload.glb" in message
    # The reference is echoed as the client wrote it (shortened); nothing else names a server path.
    assert str(data_dir) not in message and str(tmp_path) not in message.replace(reference[:77], "")
    assert not {str(secret), str(big), str(data_dir / "service.sqlite3"), str(data_dir / "service.lock")} \
        & set(opened_files), opened_files
    assert client.get("/scenes").json()["items"] == scenes_before  # nothing stored
    assert list((data_dir / "tmp").iterdir()) == []


def test_self_contained_uploads_still_work(client: httpx.Client) -> None:
    r = client.post("/scenes", content=box_scene_glb(), headers=GLB)
    assert r.status_code == 201, r.text


# -- DNS rebinding ------------------------------------------------------------------------------------------
def test_loopback_service_without_token_refuses_foreign_host_names(base: str) -> None:
    port = base.rsplit(":", 1)[1]
    for host in ("attacker.example", f"attacker.example:{port}", "127.0.0.1.attacker.example", "localhost.",
                 "10.0.0.1", ""):
        r = httpx.get(f"{base}/health", headers={"Host": host})
        assert r.status_code == 400, (host, r.text)
        err = r.json()["error"]
        assert err["code"] == "host_not_allowed" and "RENDER_BUDGET_ALLOWED_HOSTS" in err["message"]
    for host in ("127.0.0.1", f"127.0.0.1:{port}", f"localhost:{port}", "LOCALHOST", f"[::1]:{port}",
                 "[::1]"):
        assert httpx.get(f"{base}/health", headers={"Host": host}).status_code == 200, host
    # HTTP/1.0 without any Host header
    with socket.create_connection(("127.0.0.1", int(port)), timeout=10) as s:
        s.sendall(b"GET /health HTTP/1.0\r\n\r\n")
        assert b" 400 " in s.recv(4096).split(b"\r\n")[0]


def test_host_allow_list_is_configurable(tmp_path: Path) -> None:
    names = "render.example,Other.Example:99,127.0.0.1"
    with server_thread(Settings(data_dir=tmp_path / "a", allowed_hosts=names)) as url:
        assert httpx.get(f"{url}/health", headers={"Host": "render.example:8765"}).status_code == 200
        assert httpx.get(f"{url}/health", headers={"Host": "other.example"}).status_code == 200
        assert httpx.get(f"{url}/health", headers={"Host": "localhost"}).status_code == 400  # not listed
    with server_thread(Settings(data_dir=tmp_path / "b", token="a-long-enough-token")) as url:
        # A token already stops a rebinding page (it cannot know the token): any name is accepted.
        assert httpx.get(f"{url}/health", headers={"Host": "render.example"}).status_code == 200
    with server_thread(Settings(data_dir=tmp_path / "c", allowed_hosts=["*"])) as url:
        assert httpx.get(f"{url}/health", headers={"Host": "anything.example"}).status_code == 200


# -- settings from the environment --------------------------------------------------------------------------
def _serve(args: list[str], env: dict[str, str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen(args, cwd=REPO_ROOT, env={**os.environ, **env}, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)


def _stop(proc: subprocess.Popen[bytes]) -> str:
    if proc.poll() is None:
        proc.terminate()
        proc.wait(30)
    assert proc.stdout is not None
    return proc.stdout.read().decode(errors="replace")


@pytest.mark.parametrize("command", [[sys.executable, "-m", "service.api.server"],
                                     [str(Path(sys.executable).parent / "render-budget"), "serve"]])
def test_environment_settings_take_effect(tmp_path: Path, command: list[str]) -> None:
    port, token = free_port(), "token-from-the-environment"
    env = {"RENDER_BUDGET_PORT": str(port), "RENDER_BUDGET_TOKEN": token,
           "RENDER_BUDGET_DATA_DIR": str(tmp_path / "env-data"), "RENDER_BUDGET_HOST": "127.0.0.1"}
    proc = _serve(command, env)
    try:
        wait_healthy(f"http://127.0.0.1:{port}", 60, proc)
        assert httpx.get(f"http://127.0.0.1:{port}/scenes").status_code == 401  # the token is in force
        auth = {"Authorization": f"Bearer {token}"}
        assert httpx.get(f"http://127.0.0.1:{port}/scenes", headers=auth).status_code == 200
        assert (tmp_path / "env-data" / "service.sqlite3").is_file()
    finally:
        _stop(proc)
    # An option given on the command line wins over its variable; the others keep theirs.
    other = free_port()
    proc = _serve([*command, "--port", str(other)], env)
    try:
        wait_healthy(f"http://127.0.0.1:{other}", 60, proc)
        assert httpx.get(f"http://127.0.0.1:{other}/scenes").status_code == 401
    finally:
        _stop(proc)


@pytest.mark.parametrize("how", ["argument", "environment"])
def test_short_token_is_one_line_that_never_shows_it(tmp_path: Path, how: str) -> None:
    secret = "s3cr7"
    args = [sys.executable, "-m", "service.api.server", "--data-dir", str(tmp_path)]
    env = {"RENDER_BUDGET_PORT": str(free_port())}
    if how == "argument":
        args += ["--token", secret]
    else:
        env["RENDER_BUDGET_TOKEN"] = secret
    proc = _serve(args, env)
    out = _stop(proc) if proc.wait(60) is not None else ""
    assert proc.returncode == 2
    lines = out.strip().splitlines()
    assert len(lines) == 1, out
    assert "token" in lines[0] and "at least 8" in lines[0] and "RENDER_BUDGET_TOKEN" in lines[0]
    assert secret not in out and "Traceback" not in out and "pydantic" not in out


# -- bodies that stall or overflow --------------------------------------------------------------------------
def _raw_response(port: int, request: bytes, wait_s: float = 10.0) -> tuple[bytes, float, bool]:
    """Send ``request`` and read the answer; (response bytes, seconds until the first byte, whether the
    server closed the connection afterwards)."""
    with socket.create_connection(("127.0.0.1", port), timeout=wait_s) as s:
        t0 = time.monotonic()
        s.sendall(request)
        data = s.recv(65536)
        first = time.monotonic() - t0
        closed = False
        try:
            while chunk := s.recv(65536):
                data += chunk
            closed = True
        except TimeoutError:
            pass
        return data, first, closed


@pytest.mark.parametrize("path,ctype", [("/scenes", "model/gltf-binary"), ("/jobs", "application/json"),
                                        ("/stores/" + "f" * 32 + "/query", "application/json")])
def test_a_stalled_body_is_cut_off(base: str, data_dir: Path, path: str, ctype: str) -> None:
    port = int(base.rsplit(":", 1)[1])
    head = (f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: {ctype}\r\n"
            "Content-Length: 60000\r\n\r\n").encode()
    data, first, closed = _raw_response(port, head + b"{" + b" " * 999)  # then nothing more
    status = data.split(b"\r\n", 1)[0]
    assert b" 408 " in status, data[:300]
    assert 0.9 < first < 8.0  # the configured 1 s, not forever
    assert closed  # the connection is given back
    assert json.loads(data.split(b"\r\n\r\n", 1)[1])["error"]["code"] == "request_timeout"
    assert list((data_dir / "tmp").iterdir()) == []


def test_oversized_chunked_query_body_is_413(client: httpx.Client) -> None:
    def chunks() -> Iterator[bytes]:
        yield b'{"position": [0, 0, 0], "direction": [0, 1, 0], "error_budget": 0.1, "pad": "'
        for _ in range(100):
            yield b"x" * 8192
        yield b'"}'

    r = client.post("/stores/" + "f" * 32 + "/query", content=chunks(),
                    headers={"Content-Type": "application/json"})
    assert r.status_code == 413, r.text
    assert r.json()["error"]["code"] == "payload_too_large" and "limit" in r.json()["error"]["message"]


# -- one set of camera limits -----------------------------------------------------------------------------
def _camera(matrix: list[list[float]], vfov: float = 0.7) -> dict[str, Any]:
    return {"matrix_world": matrix, "vfov": vfov, "width": 16, "height": 12}


def test_render_and_evaluate_refuse_what_the_simulator_cannot_take(client: httpx.Client) -> None:
    scene = client.post("/scenes", content=box_scene_glb(), headers=GLB).json()["id"]
    good = look_at_matrix((0.0, -3.0, 1.5), (0.0, 0.0, 0.4))
    far = [row[:] for row in good]
    far[0][3] = 3.5e38  # beyond float32: the 500
    beyond = [row[:] for row in good]
    beyond[1][3] = -2e9  # finite in float32, beyond the coordinate limit
    flat = [row[:] for row in good]
    for i in range(3):
        flat[i][1] = flat[i][0] * 1.0000001  # two (nearly) parallel axes: no orientation
    for route in ("/render", "/evaluate"):
        for camera, needle in ((_camera(far), "matrix_world"), (_camera(beyond), "matrix_world"),
                               (_camera(good, 1e-300), "vfov"), (_camera(good, VFOV_MAX), "vfov"),
                               (_camera(flat), "parallel")):
            r = client.post(route, json={"scene_id": scene, "camera": camera})
            assert r.status_code == 422, (route, camera, r.text)
            assert needle in r.text
    edge = [row[:] for row in good]
    edge[0][3], edge[1][3] = 1e9, -1e9  # the limits themselves render
    for camera in (_camera(edge), _camera(good, VFOV_MIN), _camera(good, float(np.nextafter(VFOV_MAX, 0)))):
        r = client.post("/render", json={"scene_id": scene, "camera": camera, "format": "exr"})
        assert r.status_code == 200, r.text
        assert base64.b64decode(r.json()["image_base64"])[:4] == b"\x76\x2f\x31\x01"


def test_a_job_the_simulator_could_not_run_is_refused_at_submission(client: httpx.Client) -> None:
    scene = client.post("/scenes", content=box_scene_glb(), headers=GLB).json()["id"]
    for patch in ({"vfov": 1e-300}, {"vfov": VFOV_MAX}, {"resolution": [16385, 10]},
                  {"resolution": [16384, 1]}):  # aspect 16384: sizes derived from it would not render
        path = camera_path(2)
        path["frames"][1].update(patch)
        r = client.post("/jobs", json={"scene_id": scene, "camera_path": path})
        assert r.status_code == 422, (patch, r.text)
    path = camera_path(2)
    path["frames"][0]["matrix_world"][2][3] = 1e10
    assert client.post("/jobs", json={"scene_id": scene, "camera_path": path}).status_code == 422
    path = camera_path(2)
    path["frames"][0] = {"time": 0.0, "position": [0, -3, 1], "direction": [0, 0, 1], "up": [0, 0, 5],
                         "vfov": 0.7, "resolution": [64, 48]}  # up parallel to the view direction
    r = client.post("/jobs", json={"scene_id": scene, "camera_path": path})
    assert r.status_code == 422 and "parallel" in r.text
    assert client.get("/jobs").json()["items"] == []  # nothing was queued


def test_405_names_every_method_of_the_path(client: httpx.Client) -> None:
    for path, allowed in (("/jobs/x", {"GET", "DELETE"}), ("/scenes", {"GET", "POST"}),
                          ("/stores/x/query", {"POST"}), ("/health", {"GET"}), ("/jobs/x/cancel", {"POST"})):
        r = client.request("PATCH", path)
        assert r.status_code == 405 and r.json()["error"]["code"] == "method_not_allowed"
        assert {m.strip() for m in r.headers["allow"].split(",")} == allowed, (path, r.headers["allow"])
