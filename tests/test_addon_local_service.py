"""The add-on's "start a local service" path: spawn `render-budget serve` on loopback, talk to it, stop it."""

from __future__ import annotations

import socket
import sys
import time

import pytest

from addon.core.client import ServiceUnavailable
from addon.core.local_service import LocalService, free_port

pytestmark = pytest.mark.service


def test_local_service_starts_answers_and_stops(tmp_path) -> None:
    svc = LocalService(sys.executable, free_port(), tmp_path / "data")
    assert svc.command[0].endswith("render-budget")  # the console script next to the interpreter
    svc.start(ready_timeout_s=120)
    try:
        assert svc.running()
        health = svc.client().health()
        assert health["status"] == "ok" and "mobile" in health["profiles"]
        assert (tmp_path / "data").is_dir()
    finally:
        svc.stop()
    assert not svc.running()
    with pytest.raises(ServiceUnavailable):
        svc.client(timeout_s=2).health()


def test_local_service_that_cannot_start_reports_its_log(tmp_path) -> None:
    with socket.socket() as busy:  # the port is taken: uvicorn exits, we say why
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        svc = LocalService(sys.executable, busy.getsockname()[1], tmp_path / "data")
        with pytest.raises((RuntimeError, TimeoutError)) as info:
            svc.start(ready_timeout_s=60)
    assert not svc.running()
    assert "exited" in str(info.value) or "did not answer" in str(info.value)


def test_stopping_the_local_service_mid_job_leaves_no_process(tmp_path) -> None:
    """The add-on's local service renders with a process pool; stopping it (Blender quitting, the add-on
    disabled) takes the pool and multiprocessing's resource tracker with it."""
    from api_support import teapot_scene_glb
    from test_api_durability import descendants, durable_spec, wait_gone

    svc = LocalService(sys.executable, free_port(), tmp_path / "data", eval_workers=2)
    svc.start(ready_timeout_s=120)
    try:
        glb = tmp_path / "scene.glb"
        glb.write_bytes(teapot_scene_glb())
        client = svc.client()
        job = client.submit_job(durable_spec(client.upload_scene(glb)["id"]))
        deadline = time.monotonic() + 120
        while client.job(job["id"])["progress"]["evaluations"] == 0:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert svc.process is not None
        children = descendants(svc.process.pid)
        assert len(children) >= 3, [p.cmdline() for p in children]
    finally:
        svc.stop()
    assert wait_gone(children) == []
