"""The add-on's "start a local service" path: spawn `render-budget serve` on loopback, talk to it, stop it."""

from __future__ import annotations

import socket
import sys

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
