"""Property-based fuzzing of the service's own OpenAPI (schemathesis): no input causes a server error.

Every operation gets positive and negative cases; operations on scenes and stores are fuzzed twice, once
with random ids and once pinned to a real uploaded scene and a real store, so generated bodies reach the
renderer, the evaluator and the store lookup rather than stopping at 404."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import schemathesis
from api_support import server_thread, sse_events, teapot_scene_glb, tiny_job
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode

from service.api import Settings

pytestmark = [pytest.mark.service, pytest.mark.slow]

EXAMPLES = {GenerationMode.POSITIVE: 10, GenerationMode.NEGATIVE: 6}


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    data = tmp_path_factory.mktemp("api-fuzz")
    # Small preview limit: generated cameras must not make the fuzz a rendering benchmark.
    with server_thread(Settings(data_dir=data, job_workers=1, max_upload_bytes=1 << 20,
                                max_render_pixels=24 * 24)) as url:
        yield url


@pytest.fixture(scope="module")
def real_ids(base: str) -> dict[str, str]:
    with httpx.Client(base_url=base, timeout=120) as c:
        scene = c.post("/scenes", content=teapot_scene_glb(), headers={"Content-Type": "model/gltf-binary"})
        scene_id = scene.json()["id"]
        job = c.post("/jobs", json=tiny_job(scene_id)).json()
        assert sse_events(c, f"/jobs/{job['id']}/events")[-1][0] == "done"
        store_id = c.get(f"/jobs/{job['id']}").json()["store_id"]
    return {"scene_id": scene_id, "store_id": store_id, "job_id": job["id"]}


def _pin_scene(case: schemathesis.Case, scene_id: str) -> schemathesis.Case:
    if isinstance(case.body, dict) and "scene_id" in case.body:
        case.body["scene_id"] = scene_id
    return case


def _fuzz(base: str, op: Any, mode: GenerationMode, seen: dict[str, set[int]], **fixed: Any) -> None:
    scene_id = fixed.pop("pin_scene", None)
    strategy = op.as_strategy(generation_mode=mode, **fixed)
    if scene_id is not None:
        strategy = strategy.map(lambda case: _pin_scene(case, scene_id))

    @settings(max_examples=EXAMPLES[mode], deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(case=strategy)
    def check(case: schemathesis.Case) -> None:
        response = case.call(base_url=base, timeout=60)
        assert response.status_code < 500, (case.method, case.path, case.body, response.text)
        seen.setdefault(case.operation.label, set()).add(response.status_code)
        if response.status_code >= 400:
            assert set(response.json()["error"]) == {"status", "code", "message", "details"}

    try:
        check()
    except Unsatisfiable:
        # No negative input exists for operations without parameters (GET /health).
        assert mode == GenerationMode.NEGATIVE


def test_openapi_fuzzing_finds_no_server_error(base: str, real_ids: dict[str, str], tmp_path: Path) -> None:
    schema = schemathesis.openapi.from_url(f"{base}/openapi.json")
    operations = [r.ok() for r in schema.get_all_operations()]
    assert len(operations) >= 10
    seen: dict[str, set[int]] = {}
    for op in operations:
        for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):
            _fuzz(base, op, mode, seen)
            if "{store_id}" in op.path:
                _fuzz(base, op, mode, seen, path_parameters={"store_id": real_ids["store_id"]})
            elif "{scene_id}" in op.path:
                _fuzz(base, op, mode, seen, path_parameters={"scene_id": real_ids["scene_id"]})
            elif op.method.upper() == "POST" and op.path in ("/render", "/evaluate"):
                _fuzz(base, op, mode, seen, pin_scene=real_ids["scene_id"])
    assert len(seen) == len(operations)
    # Pinned ids got past the 404s: some query, render or evaluate request really succeeded.
    assert 200 in seen["POST /stores/{store_id}/query"]
    assert 200 in seen["GET /stores/{store_id}"]
    # The server is still healthy and wrote nothing outside its data directory.
    assert httpx.get(f"{base}/health").status_code == 200
    assert list(tmp_path.iterdir()) == []
