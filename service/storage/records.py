"""What the service keeps, as values: scene, job, event and store records, keyset-paginated listings
(:class:`Page` and its cursors), and the refusal to delete what is still in use (:class:`Conflict`)."""

from __future__ import annotations

import base64
import binascii
import json
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Generic, TypeVar

#: Stored scene files: glTF binaries and render-budget scene files (sim_core.loaders.scene_file).
SCENE_SUFFIXES = (".glb", ".rbscene")
JOB_STATES = ("queued", "running", "done", "failed", "cancelled")
TERMINAL_STATES = frozenset({"done", "failed", "cancelled"})


class Conflict(Exception):
    """The operation would take away something that is still in use (the message says what)."""


T = TypeVar("T")


@dataclass(frozen=True)
class Page(Generic[T]):
    """One page of a listing, newest first; ``next_cursor`` asks for the following page (None: last)."""

    items: list[T]
    next_cursor: str | None


def encode_cursor(created: float, item_id: str) -> str:
    return base64.urlsafe_b64encode(json.dumps([created, item_id]).encode()).decode().rstrip("=")


def decode_cursor(cursor: str) -> tuple[float, str]:
    """The position a cursor stands for; ValueError for anything this module did not make."""
    try:
        created, item_id = json.loads(base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)))
        if isinstance(created, bool) or not isinstance(created, int | float) or not isinstance(item_id, str):
            raise ValueError
        return float(created), item_id
    except (ValueError, TypeError, binascii.Error, UnicodeDecodeError):
        raise ValueError("invalid cursor (use the next_cursor of a previous page)") from None


@dataclass(frozen=True)
class SceneRecord:
    id: str
    size: int
    content_hash: str
    stats: dict[str, Any]
    inert: dict[str, str]
    cameras: int
    created: float


@dataclass(frozen=True)
class JobRecord:
    id: str
    scene_id: str
    spec_json: str  # the request as stored: decoded by `spec` when first read, never by a progress poll
    state: str
    progress: dict[str, Any]
    error: str | None
    store_id: str | None
    cancel_requested: bool
    attempts: int
    created: float
    started: float | None
    finished: float | None
    elapsed_s: float

    @cached_property
    def spec(self) -> dict[str, Any]:
        """The job's request. Its camera path can hold thousands of frames, and clients poll a running job
        for its progress: decoding it at every read was about 40 % of the service's own CPU during a job."""
        return json.loads(self.spec_json)

    @property
    def terminal(self) -> bool:
        return self.state in TERMINAL_STATES


@dataclass(frozen=True)
class JobEvent:
    job_id: str
    seq: int
    kind: str
    data: dict[str, Any]
    created: float


@dataclass(frozen=True)
class StoreRecord:
    id: str
    scene_id: str
    job_id: str
    body: str
    size: int
    created: float


def is_hex_id(value: str, length: int) -> bool:
    """True for exactly ``length`` lowercase hex digits (ids are never paths)."""
    return len(value) == length and all(c in "0123456789abcdef" for c in value)
