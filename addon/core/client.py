"""REST client for the render-budget service (standard library only: runs in a stock Blender)."""

from __future__ import annotations

import base64
import json
import math
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Any

LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})


class ServiceError(RuntimeError):
    """The service answered with an error status; `status` and the service's message are kept."""

    def __init__(self, status: int, message: str, body: Any = None) -> None:
        super().__init__(f"service error {status}: {message}")
        self.status = status
        self.message = message
        self.body = body


class ServiceUnavailable(ServiceError):
    """No service answered at the URL (down, wrong port, timed out)."""

    def __init__(self, url: str, reason: str) -> None:
        super().__init__(0, f"no render-budget service at {url} ({reason})")


@dataclass(frozen=True)
class RenderedImage:
    """A preview image as returned by POST /render: encoded bytes plus the service's metadata."""

    data: bytes
    content_type: str
    metadata: dict[str, Any]

    @property
    def extension(self) -> str:
        return ".exr" if "exr" in self.content_type else ".png"


def normalise_base_url(url: str) -> str:
    """Validate a service URL (http/https with a host) and strip a trailing slash."""
    url = url.strip()
    parsed = urllib.parse.urlparse(url)
    if parsed.scheme not in ("http", "https") or not parsed.hostname:
        raise ValueError(f"service URL must look like http://host:port, got {url!r}")
    if parsed.query or parsed.fragment:
        raise ValueError(f"service URL must not carry a query or fragment: {url!r}")
    return url.rstrip("/")


def is_loopback(url: str) -> bool:
    """True when the URL points at this machine (no token needed, works without online access)."""
    host = urllib.parse.urlparse(url).hostname or ""
    return host in LOOPBACK_HOSTS or host.startswith("127.")


class ServiceClient:
    """Thin synchronous client; every method raises ServiceError/ServiceUnavailable on failure.

    It is safe to use from a worker thread (it touches no Blender data).
    """

    def __init__(self, base_url: str, token: str | None = None, timeout_s: float = 30.0) -> None:
        self.base_url = normalise_base_url(base_url)
        self.token = token or None
        if not (timeout_s > 0 and math.isfinite(timeout_s)):
            raise ValueError(f"timeout must be positive, got {timeout_s}")
        self.timeout_s = timeout_s

    # -- transport -------------------------------------------------------------------------------------
    def _request(
        self,
        method: str,
        path: str,
        *,
        body: bytes | None = None,
        content_type: str | None = None,
        timeout_s: float | None = None,
    ) -> tuple[bytes, dict[str, str]]:
        url = self.base_url + path
        headers = {"Accept": "application/json, image/png, image/x-exr, */*"}
        if content_type:
            headers["Content-Type"] = content_type
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        req = urllib.request.Request(url, data=body, method=method, headers=headers)
        try:
            with urllib.request.urlopen(req, timeout=timeout_s or self.timeout_s) as resp:
                return resp.read(), {k.lower(): v for k, v in resp.headers.items()}
        except urllib.error.HTTPError as err:
            raw = err.read()
            try:
                payload = json.loads(raw.decode("utf-8")) if raw else None
            except (UnicodeDecodeError, json.JSONDecodeError):
                payload = raw.decode("utf-8", "replace")
            raise ServiceError(err.code, _error_message(payload, err.reason), payload) from None
        except (urllib.error.URLError, ConnectionError, TimeoutError) as err:
            reason = getattr(err, "reason", err)
            raise ServiceUnavailable(self.base_url, str(reason)) from None

    def _json(self, method: str, path: str, payload: Any = None, timeout_s: float | None = None) -> Any:
        body = None
        if payload is not None:
            body = json.dumps(payload, allow_nan=False).encode("utf-8")
        raw, _ = self._request(
            method, path, body=body, content_type="application/json" if body else None, timeout_s=timeout_s
        )
        if not raw:
            return None
        try:
            return json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise ServiceError(200, f"service sent invalid JSON for {method} {path}: {err}") from None

    # -- endpoints -------------------------------------------------------------------------------------
    def health(self, timeout_s: float | None = None) -> dict[str, Any]:
        return self._json("GET", "/health", timeout_s=timeout_s)

    def upload_scene(self, scene_path: str | Path) -> dict[str, Any]:
        """POST /scenes with a render-budget scene file (what the add-on sends) or a .glb; returns id,
        statistics (with the translation ``notes`` of a scene file) and inert parameters."""
        data = Path(scene_path).read_bytes()
        if data[:4] == b"glTF":
            content_type = "model/gltf-binary"
        else:
            from sim_core.loaders.scene_file import (  # lazy: the native core loads on first use
                MEDIA_TYPE,
                is_scene_file,
            )

            if not is_scene_file(data[:64]):
                raise ValueError(f"{scene_path} is neither a render-budget scene file nor a binary glTF "
                                 "(.glb)")
            content_type = MEDIA_TYPE
        raw, _ = self._request("POST", "/scenes", body=data, content_type=content_type)
        return json.loads(raw.decode("utf-8"))

    def scene(self, scene_id: str) -> dict[str, Any]:
        return self._json("GET", f"/scenes/{_segment(scene_id)}")

    def submit_job(self, payload: dict[str, Any]) -> dict[str, Any]:
        return self._json("POST", "/jobs", payload)

    def job(self, job_id: str) -> dict[str, Any]:
        return self._json("GET", f"/jobs/{_segment(job_id)}")

    def cancel_job(self, job_id: str) -> dict[str, Any] | None:
        return self._json("POST", f"/jobs/{_segment(job_id)}/cancel")

    def store_text(self, store_id: str) -> str:
        """GET /stores/{id} as the raw JSON text (kept verbatim in the .blend)."""
        raw, _ = self._request("GET", f"/stores/{_segment(store_id)}")
        text = raw.decode("utf-8")
        json.loads(text)  # fail here, not at playback, if the service sent garbage
        return text

    def query(self, store_id: str, payload: dict[str, Any]) -> dict[str, Any]:
        return self._json("POST", f"/stores/{_segment(store_id)}/query", payload)

    def evaluate(self, payload: dict[str, Any], timeout_s: float | None = None) -> dict[str, Any]:
        return self._json("POST", "/evaluate", payload, timeout_s=timeout_s)

    def render(self, payload: dict[str, Any], timeout_s: float | None = None) -> RenderedImage:
        body = json.dumps(payload, allow_nan=False).encode("utf-8")
        raw, headers = self._request(
            "POST", "/render", body=body, content_type="application/json", timeout_s=timeout_s
        )
        ctype = headers.get("content-type", "")
        if ctype.startswith("application/json"):
            doc = json.loads(raw.decode("utf-8"))
            return _image_from_json(doc)
        meta: dict[str, Any] = {}
        for key, value in headers.items():
            if key.startswith("x-render-budget-"):
                try:
                    meta[key.removeprefix("x-render-budget-")] = json.loads(value)
                except json.JSONDecodeError:
                    meta[key.removeprefix("x-render-budget-")] = value
        return RenderedImage(raw, ctype, meta)


def _image_from_json(doc: dict[str, Any]) -> RenderedImage:
    for key in ("image_base64", "image", "data"):
        if isinstance(doc.get(key), str):
            data = base64.b64decode(doc[key])
            fmt = str(doc.get("format", "png")).lower()
            ctype = "image/x-exr" if fmt == "exr" else "image/png"
            meta = {k: v for k, v in doc.items() if k != key}
            return RenderedImage(data, ctype, meta)
    raise ServiceError(200, "render response carries no image")


def _segment(value: str) -> str:
    if not value or "/" in value:
        raise ValueError(f"invalid id {value!r}")
    return urllib.parse.quote(value, safe="")


def _error_message(payload: Any, fallback: str) -> str:
    if isinstance(payload, dict):
        for key in ("detail", "message", "error"):
            v = payload.get(key)
            if isinstance(v, str):
                return v
            if isinstance(v, dict) and isinstance(v.get("message"), str):
                return v["message"]
            if isinstance(v, list) and v:
                return "; ".join(str(item.get("msg", item)) if isinstance(item, dict) else str(item)
                                 for item in v)
    if isinstance(payload, str) and payload:
        return payload[:500]
    return str(fallback)
