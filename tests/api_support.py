"""Helpers for the REST API tests: real .glb scenes, camera paths, and real uvicorn servers."""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pygltflib

from service.store.camera import look_matrix

REPO_ROOT = Path(__file__).resolve().parent.parent
MODELS_DIR = REPO_ROOT / "assets" / "models"

# Blender (Z up) -> glTF (Y up): (x, y, z) -> (x, z, -y); the loader applies the inverse.
_TO_GLTF = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def glb_bytes(meshes: list[dict[str, Any]], *, lights: list[dict[str, Any]] = ()) -> bytes:  # type: ignore[assignment]
    """A binary glTF with one node per mesh (positions in Blender's frame, converted here) and
    KHR_lights_punctual point lights ({"position": (x, y, z), "intensity": candela})."""
    blob = bytearray()
    gltf = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"), scene=0)
    root_nodes: list[int] = []

    def view(data: bytes, target: int) -> int:
        while len(blob) % 4:
            blob.append(0)
        gltf.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data),
                                                     target=target))
        blob.extend(data)
        return len(gltf.bufferViews) - 1

    for m in meshes:
        pos = (np.asarray(m["positions"], dtype=np.float64) @ _TO_GLTF.T).astype(np.float32)
        tri = np.asarray(m["triangles"], dtype=np.uint32)
        pv = view(pos.tobytes(), pygltflib.ARRAY_BUFFER)
        finite = pos[np.isfinite(pos).all(axis=1)] if np.isfinite(pos).any() else np.zeros((1, 3), np.float32)
        gltf.accessors.append(pygltflib.Accessor(
            bufferView=pv, componentType=pygltflib.FLOAT, count=len(pos), type=pygltflib.VEC3,
            min=finite.min(axis=0).tolist(), max=finite.max(axis=0).tolist()))
        pa = len(gltf.accessors) - 1
        iv = view(tri.reshape(-1).tobytes(), pygltflib.ELEMENT_ARRAY_BUFFER)
        gltf.accessors.append(pygltflib.Accessor(bufferView=iv, componentType=pygltflib.UNSIGNED_INT,
                                                 count=int(tri.size), type=pygltflib.SCALAR))
        ia = len(gltf.accessors) - 1
        gltf.materials.append(pygltflib.Material(
            pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                baseColorFactor=[*m.get("color", (0.8, 0.8, 0.8)), 1.0],
                metallicFactor=float(m.get("metallic", 0.0)),
                roughnessFactor=float(m.get("roughness", 0.6)))))
        gltf.meshes.append(pygltflib.Mesh(primitives=[pygltflib.Primitive(
            attributes=pygltflib.Attributes(POSITION=pa), indices=ia, material=len(gltf.materials) - 1)]))
        gltf.nodes.append(pygltflib.Node(mesh=len(gltf.meshes) - 1, name=m.get("name", "mesh")))
        root_nodes.append(len(gltf.nodes) - 1)
    if lights:
        gltf.extensionsUsed = ["KHR_lights_punctual"]
        gltf.extensions = {"KHR_lights_punctual": {"lights": [
            {"type": "point", "intensity": float(light.get("intensity", 5000.0)), "color": [1.0, 1.0, 1.0]}
            for light in lights]}}
        for i, light in enumerate(lights):
            p = np.asarray(light["position"], dtype=np.float64) @ _TO_GLTF.T
            gltf.nodes.append(pygltflib.Node(translation=p.tolist(), name=f"light{i}",
                                             extensions={"KHR_lights_punctual": {"light": i}}))
            root_nodes.append(len(gltf.nodes) - 1)
    gltf.scenes.append(pygltflib.Scene(nodes=root_nodes))
    gltf.buffers.append(pygltflib.Buffer(byteLength=len(blob)))
    gltf.set_binary_blob(bytes(blob))
    return b"".join(gltf.save_to_bytes())


def plane(size: float = 4.0, z: float = 0.0) -> dict[str, Any]:
    s = size / 2
    return {"name": "ground", "positions": [(-s, -s, z), (s, -s, z), (s, s, z), (-s, s, z)],
            "triangles": [(0, 1, 2), (0, 2, 3)], "color": (0.6, 0.6, 0.6)}


def box(center: tuple[float, float, float] = (0.0, 0.0, 0.5), half: float = 0.5) -> dict[str, Any]:
    c = np.asarray(center)
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], dtype=np.float64)
    faces = [(0, 2, 1), (1, 2, 3), (4, 5, 6), (5, 7, 6), (0, 1, 4), (1, 5, 4),
             (2, 6, 3), (3, 6, 7), (0, 4, 2), (2, 4, 6), (1, 3, 5), (3, 7, 5)]
    return {"name": "box", "positions": (c + half * corners).tolist(), "triangles": faces,
            "color": (0.8, 0.3, 0.2), "metallic": 0.5, "roughness": 0.2}


def teapot_mesh() -> dict[str, Any]:
    """The bundled Utah teapot (OBJ, Y up), scaled to about 1 m and standing on z = 0."""
    verts: list[list[float]] = []
    faces: list[tuple[int, int, int]] = []
    for line in (MODELS_DIR / "teapot.obj").read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            x, y, z = (float(v) for v in parts[1:4])
            verts.append([x, -z, y])  # OBJ Y-up -> Blender Z-up
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) for p in parts[1:]]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            faces.extend((idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1))
    v = np.asarray(verts)
    v -= [(v[:, 0].min() + v[:, 0].max()) / 2, (v[:, 1].min() + v[:, 1].max()) / 2, v[:, 2].min()]
    v /= np.ptp(v, axis=0).max()
    return {"name": "teapot", "positions": v.tolist(), "triangles": faces, "color": (0.9, 0.7, 0.3),
            "metallic": 0.3, "roughness": 0.3}


def teapot_scene_glb() -> bytes:
    return glb_bytes([teapot_mesh(), plane()], lights=[{"position": (2.0, -2.0, 3.0), "intensity": 8000.0}])


def teapot_scene_file(directory: Path) -> Path:
    """The teapot scene written as ``directory/teapot.glb``."""
    path = directory / "teapot.glb"
    path.write_bytes(teapot_scene_glb())
    return path


def box_scene_glb() -> bytes:
    return glb_bytes([box(), plane()], lights=[{"position": (2.0, -2.0, 3.0), "intensity": 8000.0}])


def look_at_matrix(eye: tuple[float, float, float], target: tuple[float, float, float]) -> list[list[float]]:
    """Blender camera world matrix (looks down local -Z, +Y up) at ``eye`` towards ``target``."""
    e, t = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    return look_matrix(e, t - e).tolist()


def camera_path(n: int = 3, radius: float = 3.0, height: float = 1.5) -> dict[str, Any]:
    """A short arc around the origin, looking at the scene's middle."""
    frames = []
    for i in range(n):
        a = -0.6 + 0.3 * i
        eye = (radius * math.sin(a), -radius * math.cos(a), height)
        frames.append({"time": i / 30.0, "matrix_world": look_at_matrix(eye, (0.0, 0.0, 0.4)),
                       "vfov": 0.6911, "resolution": [64, 48]})
    return {"version": 1, "fps": 30.0, "frames": frames}


def tiny_job(scene_id: str, *, resolution: tuple[int, int] = (16, 12), seed: int = 1,
             depth_values: tuple[int, ...] = (0, 1)) -> dict[str, Any]:
    """Two searched parameters (sampling x max ray depth, 2 x 2 = 4 settings, enumerated exactly),
    everything else fixed cheap, octree depth 0, tiny evaluation images."""
    return {
        "scene_id": scene_id,
        "camera_path": camera_path(3),
        "space": {"sampling": ["undersample_2x2", "1spp"], "max_depth": list(depth_values),
                  "shadow_samples": [1], "ao_samples": [0], "env_filter": ["off"],
                  "resolution_scale": [1.0], "normal_threshold_deg": [20.0], "multirate": [False]},
        "parameters": ["sampling", "max_depth"],
        "options": {"max_depth": 0, "population": 4, "generations": 2, "seed": seed, "exhaustive_limit": 64,
                    "eval_width": resolution[0], "eval_height": resolution[1]},
        "profile": "mobile",
    }


RUN_STATISTICS = ("evaluations", "cache_hits", "elapsed_s", "executor")


def comparable(store_json: str) -> dict[str, Any]:
    """The store without the statistics of the run that made it (renders, hits, time, executor)."""
    doc = json.loads(store_json)
    for key in RUN_STATISTICS:
        doc["meta"].pop(key)
    return doc


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_healthy(base_url: str, timeout: float = 60.0, proc: subprocess.Popen[bytes] | None = None,
                 thread: threading.Thread | None = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"server exited with {proc.returncode}")
        if thread is not None and not thread.is_alive():
            raise RuntimeError("server thread died during start-up")
        with contextlib.suppress(httpx.HTTPError):
            if httpx.get(f"{base_url}/health", timeout=2.0).status_code == 200:
                return
        time.sleep(0.05)
    raise TimeoutError(f"{base_url} did not become healthy in {timeout} s")


@contextlib.contextmanager
def server_thread(settings: Any) -> Iterator[str]:
    """Real uvicorn in a thread of this process (fast to start; same process as the test)."""
    import uvicorn

    from service.api import create_app

    port = free_port()
    config = uvicorn.Config(create_app(settings), host="127.0.0.1", port=port, log_level="warning",
                            access_log=False, timeout_graceful_shutdown=5)
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(base, thread=thread)
        yield base
    finally:
        server.should_exit = True
        thread.join(30)


class ServerProcess:
    """Real uvicorn in a child process (``python -m service.api.server``), killable with SIGKILL."""

    def __init__(self, data_dir: Path, *, host: str = "127.0.0.1", token: str | None = None,
                 dask_scheduler: str | None = None, extra_env: dict[str, str] | None = None,
                 extra_args: list[str] | None = None) -> None:
        self.port = free_port()
        self.host = host
        self.base_url = f"http://127.0.0.1:{self.port}"
        args = [sys.executable, "-m", "service.api.server", "--host", host, "--port", str(self.port),
                "--data-dir", str(data_dir), "--log-level", "warning"]
        if token:
            args += ["--token", token]
        if dask_scheduler:
            args += ["--dask-scheduler", dask_scheduler]
        args += extra_args or []
        env = {**os.environ, **(extra_env or {})}
        self.proc = subprocess.Popen(args, cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT)

    def wait_healthy(self, timeout: float = 60.0) -> ServerProcess:
        wait_healthy(self.base_url, timeout, self.proc)
        return self

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(30)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.kill()

    def output(self) -> str:
        if self.proc.stdout is None or self.proc.poll() is None:
            return ""
        return self.proc.stdout.read().decode(errors="replace")


def sse_events(client: httpx.Client, url: str, timeout: float = 120.0) -> list[tuple[str, dict[str, Any]]]:
    """Read a server-sent-event stream to its end; returns (event, data) pairs."""
    events: list[tuple[str, dict[str, Any]]] = []
    kind, data = "message", ""
    with client.stream("GET", url, timeout=timeout) as r:
        assert r.status_code == 200, r.read()
        assert r.headers["content-type"].startswith("text/event-stream")
        for line in r.iter_lines():
            if line.startswith("event:"):
                kind = line[6:].strip()
            elif line.startswith("data:"):
                data += line[5:].strip()
            elif line == "":
                if data:
                    events.append((kind, json.loads(data)))
                kind, data = "message", ""
    return events
