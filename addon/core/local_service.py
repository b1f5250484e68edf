"""Start and stop a local `render-budget serve` process (pure: subprocess + the REST client)."""

from __future__ import annotations

import os
import socket
import subprocess
import time
from pathlib import Path

from .client import ServiceClient, ServiceError


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free right now on `host` (for tests and for 'port 0' in preferences)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def serve_command(python: str | Path, port: int, data_dir: str | Path, token: str | None = None,
                  host: str = "127.0.0.1", eval_workers: int | None = None) -> list[str]:
    """Command line that runs the service with `python`: its `render-budget` script when present."""
    python = Path(python)
    if not python.is_file():
        raise FileNotFoundError(f"Python interpreter not found: {python}")
    if not 0 < int(port) < 65536:
        raise ValueError(f"invalid port {port}")
    script = python.parent / ("render-budget.exe" if os.name == "nt" else "render-budget")
    head = [str(script)] if script.is_file() else [
        str(python), "-c", "import sys; from service.cli import main; sys.exit(main(sys.argv[1:]))"]
    cmd = [*head, "serve", "--host", host, "--port", str(int(port)), "--data-dir", str(data_dir)]
    if token:
        cmd += ["--token", token]
    if eval_workers is not None:
        cmd += ["--eval-workers", str(int(eval_workers))]
    return cmd


class LocalService:
    """A `render-budget serve` child process bound to loopback; stopped explicitly or at exit."""

    def __init__(self, python: str | Path, port: int, data_dir: str | Path, token: str | None = None,
                 eval_workers: int | None = None) -> None:
        self.port = int(port)
        self.data_dir = Path(data_dir)
        self.token = token or None
        self.command = serve_command(python, self.port, self.data_dir, self.token,
                                     eval_workers=eval_workers)
        self.process: subprocess.Popen | None = None
        self.log_path = self.data_dir / "service.log"

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def client(self, timeout_s: float = 30.0) -> ServiceClient:
        return ServiceClient(self.url, self.token, timeout_s)

    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def start(self, ready_timeout_s: float = 60.0) -> None:
        """Spawn the service and wait until GET /health answers; raise with the log tail otherwise."""
        if self.running():
            return
        self.data_dir.mkdir(parents=True, exist_ok=True)
        log = self.log_path.open("ab")
        try:
            flags = {"start_new_session": True} if os.name != "nt" else {}
            self.process = subprocess.Popen(self.command, stdout=log, stderr=subprocess.STDOUT,
                                            stdin=subprocess.DEVNULL, **flags)
        finally:
            log.close()
        deadline = time.monotonic() + ready_timeout_s
        client = self.client(timeout_s=2.0)
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"local service exited with status {self.process.returncode}:\n"
                                   + self.log_tail())
            try:
                client.health(timeout_s=2.0)
                return
            except ServiceError:
                time.sleep(0.2)
        self.stop()
        raise TimeoutError(
            f"local service did not answer within {ready_timeout_s:.0f} s:\n" + self.log_tail())

    def stop(self, timeout_s: float = 10.0) -> None:
        """Terminate the child (SIGTERM, then SIGKILL after `timeout_s`)."""
        proc, self.process = self.process, None
        if proc is None or proc.poll() is not None:
            return
        proc.terminate()
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=timeout_s)

    def log_tail(self, lines: int = 20) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return "(no log)"

