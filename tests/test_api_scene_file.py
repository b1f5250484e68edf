"""Render-budget scene files on a real uvicorn server: uploaded beside glTF, content-addressed (same scene,
same id), validated like any upload (4xx naming the problem, no server paths), and optimised by a job."""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from api_support import box, box_scene_glb, plane, server_thread, sse_events, tiny_job
from sim_core.loaders.scene_file import MEDIA_TYPE, scene_file_bytes
from sim_core.scene_data import Light, Material, SceneData

from service.api import Settings

pytestmark = pytest.mark.service

SCENE = {"Content-Type": MEDIA_TYPE}
NOTES = [{"severity": "warning", "subject": "material 'Checker'", "message": "approximated by its mean"}]


def box_scene_data() -> SceneData:
    parts = [box(), plane()]
    pos, tri, mids = [], [], []
    offset = 0
    for i, m in enumerate(parts):
        p = np.asarray(m["positions"], dtype=np.float32)
        pos.append(p)
        tri.append(np.asarray(m["triangles"], dtype=np.int64) + offset)
        mids.append(np.full(len(m["triangles"]), i, np.uint32))
        offset += len(p)
    return SceneData(
        positions=np.concatenate(pos), triangles=np.concatenate(tri).astype(np.uint32),
        material_ids=np.concatenate(mids), object_ids=np.concatenate(mids),
        materials=[Material(base_color=(0.8, 0.3, 0.2), metallic=1.0, roughness=0.45, name="metal"),
                   Material(base_color=(0.6, 0.6, 0.6), name="ground")],
        lights=[Light(kind="point", position=(2.0, -2.0, 3.0), intensity=80.0, radius=0.1, name="key")],
        environment=(0.05, 0.06, 0.08), object_names=["box", "ground"])


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("api-scene-file")


@pytest.fixture(scope="module")
def client(data_dir: Path) -> Iterator[httpx.Client]:
    with server_thread(Settings(data_dir=data_dir, max_upload_bytes=1024 * 1024, job_workers=1)) as url, \
            httpx.Client(base_url=url, timeout=120.0) as c:
        yield c


@pytest.fixture(scope="module")
def uploaded(client: httpx.Client) -> dict[str, Any]:
    r = client.post("/scenes", content=scene_file_bytes(box_scene_data(), NOTES), headers=SCENE)
    assert r.status_code == 201, r.text
    return r.json()


def test_scene_file_upload_is_content_addressed(client: httpx.Client, uploaded: dict[str, Any],
                                                data_dir: Path) -> None:
    blob = scene_file_bytes(box_scene_data(), NOTES)
    assert uploaded["id"] == hashlib.sha256(blob).hexdigest()
    assert uploaded["stats"]["format"] == "scene" and uploaded["stats"]["notes"] == NOTES
    assert uploaded["stats"]["triangles"] == 14 and uploaded["stats"]["lights"] == 1
    assert (data_dir / "scenes" / f"{uploaded['id']}.rbscene").is_file()
    # the same scene, written again (and sent as a plain binary body), is the same scene
    again = client.post("/scenes", content=scene_file_bytes(box_scene_data(), NOTES),
                        headers={"Content-Type": "application/octet-stream"})
    assert again.status_code == 201 and again.json()["id"] == uploaded["id"]
    assert client.get(f"/scenes/{uploaded['id']}").json()["stats"]["format"] == "scene"


def test_glb_uploads_still_work_beside_scene_files(client: httpx.Client) -> None:
    r = client.post("/scenes", content=box_scene_glb(), headers={"Content-Type": "model/gltf-binary"})
    assert r.status_code == 201, r.text
    assert r.json()["stats"]["format"] == "glb" and "notes" not in r.json()["stats"]


def test_job_optimises_a_scene_file(client: httpx.Client, uploaded: dict[str, Any]) -> None:
    r = client.post("/jobs", json=tiny_job(uploaded["id"]))
    assert r.status_code == 201, r.text
    job_id = r.json()["id"]
    events = sse_events(client, f"/jobs/{job_id}/events")
    assert events[-1][0] == "done", events[-1]
    job = client.get(f"/jobs/{job_id}").json()
    assert client.get(f"/stores/{job['store_id']}").status_code == 200


def corrupt_manifest(edit) -> bytes:
    src = zipfile.ZipFile(io.BytesIO(scene_file_bytes(box_scene_data())))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "manifest.json":
                doc = json.loads(data)
                edit(doc)
                data = json.dumps(doc).encode()
            zf.writestr(info.filename, data)
    return out.getvalue()


@pytest.mark.parametrize(("body", "status", "needle"), [
    (lambda: corrupt_manifest(lambda d: d["materials"][0].update(roughness=7.0)), 422, "roughness"),
    (lambda: corrupt_manifest(lambda d: d.update(version=9)), 422, "newer"),
    (lambda: corrupt_manifest(lambda d: d["arrays"]["positions"].update(shape=[99, 3])), 422,
     "manifest says"),
    (lambda: scene_file_bytes(box_scene_data())[:300], 422, "scene file"),
    (lambda: b"PK\x03\x04" + b"\0" * 80, 400, "manifest.json"),
    (lambda: b"\x89PNG" + b"\0" * 80, 400, "not a render-budget scene file"),
])
def test_malformed_scene_files_get_a_4xx_naming_the_problem(client: httpx.Client, data_dir: Path, body,
                                                            status: int, needle: str) -> None:
    r = client.post("/scenes", content=body(), headers=SCENE)
    assert r.status_code == status, r.text
    message = r.json()["error"]["message"]
    assert needle.lower() in message.lower(), message
    assert str(data_dir) not in message and ".rbscene" not in message and "tmp" not in message
    assert list((data_dir / "tmp").iterdir()) == []


def test_octet_stream_is_told_apart_by_its_bytes(client: httpx.Client) -> None:
    r = client.post("/scenes", content=b"\x89PNG" + b"\0" * 80,
                    headers={"Content-Type": "application/octet-stream"})
    assert r.status_code == 400 and "neither" in r.json()["error"]["message"]


def test_oversize_scene_file_is_413(client: httpx.Client) -> None:
    big = box_scene_data()
    big.environment = np.random.default_rng(0).random((512, 1024, 3)).astype(np.float32)
    r = client.post("/scenes", content=scene_file_bytes(big), headers=SCENE)
    assert r.status_code == 413, r.text
