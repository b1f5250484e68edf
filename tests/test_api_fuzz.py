"""Fuzzing the real server: schemathesis with every check on the service's own OpenAPI, and valid but
extreme cameras (schemathesis alone never builds an invertible matrix near the limits). Fixed seeds and
small budgets here; a longer run (RENDER_BUDGET_FUZZ_EXAMPLES, RENDER_BUDGET_FUZZ_SEED) is recorded in
bench/RESULTS.md:

    RENDER_BUDGET_FUZZ_EXAMPLES=100 RENDER_BUDGET_FUZZ_SEED=21 .venv/bin/python -m pytest -m fuzz -s \
        tests/test_api_fuzz.py
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from api_support import camera_path, server_thread, sse_events, teapot_scene_glb, tiny_job
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from service.api import Settings
from service.store.camera import MAX_COORDINATE, MIN_AXES_VOLUME, VFOV_MAX, VFOV_MIN

pytestmark = [pytest.mark.service, pytest.mark.fuzz, pytest.mark.slow]

TESTS = Path(__file__).resolve().parent
SEED = int(os.environ.get("RENDER_BUDGET_FUZZ_SEED", "1104"))
EXAMPLES = int(os.environ.get("RENDER_BUDGET_FUZZ_EXAMPLES", "5"))
MAX_PIXELS = 24 * 24  # previews stay cheap: the fuzz is not a rendering benchmark


def _server(data_dir: Path) -> Any:
    return server_thread(Settings(data_dir=data_dir, job_workers=1, max_upload_bytes=1 << 20,
                                  max_render_pixels=MAX_PIXELS, body_read_timeout_s=10.0))


def _real_ids(base: str) -> dict[str, str]:
    """A real scene, store and finished job for the fuzzers to reach past the 404s."""
    with httpx.Client(base_url=base, timeout=120) as c:
        scene = c.post("/scenes", content=teapot_scene_glb(), headers={"Content-Type": "model/gltf-binary"})
        job = c.post("/jobs", json=tiny_job(scene.json()["id"])).json()
        assert sse_events(c, f"/jobs/{job['id']}/events")[-1][0] == "done"
        store_id = c.get(f"/jobs/{job['id']}").json()["store_id"]
    return {"scene_id": scene.json()["id"], "store_id": store_id, "job_id": job["id"]}


@pytest.fixture(scope="module")
def cameras_base(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """The extreme-camera tests have their own server: schemathesis' stateful phase deletes what it
    finds (as it should be able to)."""
    with _server(tmp_path_factory.mktemp("api-fuzz-cameras")) as url:
        yield url


@pytest.fixture(scope="module")
def real(cameras_base: str) -> dict[str, str]:
    return _real_ids(cameras_base)


def test_schemathesis_with_every_check_finds_nothing(tmp_path: Path) -> None:
    """No server error, no answer the OpenAPI document does not describe (status, content type, body
    schema, Allow header), invalid data rejected and valid data accepted (tests/schemathesis.toml lists
    the constraints JSON Schema cannot state), across the coverage, fuzzing and stateful phases."""
    with _server(tmp_path / "data") as base:
        _run_schemathesis(base, _real_ids(base), tmp_path / "data", tmp_path)


def _run_schemathesis(base: str, real: dict[str, str], data_dir: Path, tmp_path: Path) -> None:
    status_log = tmp_path / "statuses.txt"
    env = {**os.environ, "SCHEMATHESIS_HOOKS": str(TESTS / "fuzz_hooks.py"),
           "RENDER_BUDGET_FUZZ_SCENE": real["scene_id"], "RENDER_BUDGET_FUZZ_STORE": real["store_id"],
           "RENDER_BUDGET_FUZZ_JOB": real["job_id"], "RENDER_BUDGET_FUZZ_STATUS_LOG": str(status_log)}
    cli = Path(sys.executable).parent / "schemathesis"
    proc = subprocess.run(
        [str(cli), "--config-file", str(TESTS / "schemathesis.toml"), "run", f"{base}/openapi.json",
         "--checks", "all", "--seed", str(SEED), "--max-examples", str(EXAMPLES), "--workers", "1",
         "--request-timeout", "60", "--suppress-health-check", "all"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1800, check=False)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-8000:]
    counts = re.search(r"(\d+) generated, (\d+) passed", out)
    assert counts is not None, out[-3000:]
    generated, passed = int(counts.group(1)), int(counts.group(2))
    assert generated == passed and generated > 300, out[-3000:]
    answers = Counter(tuple(line.rsplit(" ", 1)) for line in status_log.read_text().splitlines())
    by_status: Counter[str] = Counter()
    for (_, status), n in answers.items():
        by_status[status] += n
    print(f"schemathesis seed {SEED}, {EXAMPLES} examples: {generated} cases, all checks passed; "
          f"{sum(by_status.values())} requests by status: {dict(sorted(by_status.items()))}")
    assert not [k for k in by_status if k.startswith("5")]
    # The real ids reached the lookup and the jobs (not only 404s).
    for reached in ("POST /stores/{store_id}/query", "GET /stores/{store_id}", "GET /jobs/{job_id}"):
        assert answers[(reached, "200")] > 0, (reached, answers)
    assert httpx.get(f"{base}/health").status_code == 200
    assert list((data_dir / "tmp").iterdir()) == []


# -- valid but extreme cameras ------------------------------------------------------------------------------
def _rotation(q: tuple[float, float, float, float]) -> np.ndarray:
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


edge_coordinates = st.sampled_from([0.0, 5e-324, -1e-300, 1e-9, 3.0, -3.0, 1e6, MAX_COORDINATE,
                                    -MAX_COORDINATE])
coordinates = st.one_of(edge_coordinates, st.floats(-MAX_COORDINATE, MAX_COORDINATE, allow_nan=False))
axis_scales = st.sampled_from([1e-300, 1e-150, 1e-30, 1e-3, 1.0, 7.5, 1e30, 1e150, 1e300])
unit_quaternions = st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 4).filter(
    lambda q: math.hypot(*q) > 1e-3)
vfovs = st.one_of(st.sampled_from([VFOV_MIN, 1e-3, 0.7, 3.0, np.nextafter(VFOV_MAX, 0.0)]),
                  st.floats(VFOV_MIN, VFOV_MAX, exclude_max=True))


@st.composite
def extreme_matrices(draw: st.DrawFn) -> list[list[float]]:
    """Camera world matrices the schema accepts: any rotation, each axis scaled by up to 1e+-300, one axis
    possibly sheared towards another down to just above the minimum volume, any allowed position."""
    axes = _rotation(draw(unit_quaternions))
    shear = draw(st.sampled_from([0.0, 0.5, 0.99, 1.0 - 1.5 * MIN_AXES_VOLUME]))
    a, b = draw(st.permutations([0, 1, 2]))[:2]
    axes[:, a] = (1 - shear) * axes[:, a] + shear * axes[:, b]
    axes /= np.linalg.norm(axes, axis=0)
    m = np.eye(4)
    m[:3, :3] = axes * np.array([draw(axis_scales) for _ in range(3)])
    m[:3, 3] = [draw(coordinates) for _ in range(3)]
    assert abs(np.linalg.det(axes)) >= MIN_AXES_VOLUME
    return m.tolist()


@st.composite
def extreme_cameras(draw: st.DrawFn) -> dict[str, Any]:
    width = draw(st.sampled_from([8, 9, 24, MAX_PIXELS // 8]))
    height = draw(st.integers(8, MAX_PIXELS // width))
    return {"matrix_world": draw(extreme_matrices()), "vfov": draw(vfovs), "width": width, "height": height}


def _fuzz_settings(examples: int) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """A fixed seed (RENDER_BUDGET_FUZZ_SEED) and budget; no example database between runs."""
    configure = settings(max_examples=examples, deadline=None, database=None,
                         suppress_health_check=list(HealthCheck))
    return lambda test: seed(SEED)(configure(test))


@pytest.mark.parametrize("route", ["/render", "/evaluate"])
def test_extreme_cameras_render_and_evaluate(cameras_base: str, real: dict[str, str], route: str) -> None:
    with httpx.Client(base_url=cameras_base, timeout=120) as c:

        @_fuzz_settings(4 * EXAMPLES)
        @given(camera=extreme_cameras(), fmt=st.sampled_from(["png", "exr"]))
        def check(camera: dict[str, Any], fmt: str) -> None:
            body: dict[str, Any] = {"scene_id": real["scene_id"], "camera": camera}
            if route == "/render":
                body["format"] = fmt
            r = c.post(route, json=body)
            assert r.status_code == 200, (camera, r.text)
            if route == "/evaluate":
                assert 0.0 <= r.json()["error"] <= 1.0 and math.isfinite(r.json()["power_w"])
            done.append(r.status_code)

        done: list[int] = []
        check()
        print(f"extreme cameras, seed {SEED}: {len(done)} x POST {route}, all 200")


def test_extreme_cameras_query_the_store(cameras_base: str, real: dict[str, str]) -> None:
    with httpx.Client(base_url=cameras_base, timeout=60) as c:

        @_fuzz_settings(8 * EXAMPLES)
        @given(matrix=extreme_matrices(), fov=vfovs,
               budget=st.sampled_from(["power_budget_w", "error_budget"]),
               by=st.sampled_from(["matrix", "direction"]))
        def check(matrix: list[list[float]], fov: float, budget: str, by: str) -> None:
            m = np.asarray(matrix)
            pose: dict[str, Any] = ({"matrix": matrix} if by == "matrix"
                                    else {"direction": (-m[:3, 2]).tolist()})
            body = {"position": m[:3, 3].tolist(), "fov": fov, budget: 0.5, **pose}
            r = c.post(f"/stores/{real['store_id']}/query", json=body)
            assert r.status_code == 200, (body, r.text)
            assert math.isfinite(r.json()["power_w"]) and math.isfinite(r.json()["error"])
            done.append(r.status_code)

        done: list[int] = []
        check()
        print(f"extreme cameras, seed {SEED}: {len(done)} store queries, all 200")


def test_a_path_of_extreme_cameras_is_optimised(cameras_base: str, real: dict[str, str]) -> None:
    """A job the service accepts runs to its end: the limits at submission are the simulator's."""
    with httpx.Client(base_url=cameras_base, timeout=120) as c:

        @_fuzz_settings(EXAMPLES)
        @given(matrices=st.lists(extreme_matrices(), min_size=1, max_size=3), fov=vfovs,
               resolution=st.sampled_from([(1, 1), (16384, 256), (256, 16384), (64, 1), (1920, 1080)]))
        def check(matrices: list[list[list[float]]], fov: float, resolution: tuple[int, int]) -> None:
            path = camera_path(len(matrices))
            for frame, m in zip(path["frames"], matrices, strict=True):
                frame.update(matrix_world=m, vfov=fov, resolution=list(resolution))
            spec = {**tiny_job(real["scene_id"], resolution=(8, 8)), "camera_path": path}
            r = c.post("/jobs", json=spec)
            assert r.status_code == 201, r.text
            events = sse_events(c, f"/jobs/{r.json()['id']}/events", timeout=600)
            assert events[-1][0] == "done", events[-1]
            done.append(len(matrices))

        done: list[int] = []
        check()
        print(f"extreme cameras, seed {SEED}: {len(done)} jobs ({sum(done)} frames), all done")
