"""Durable state of the REST service: content-addressed scene files plus SQLite (WAL) tables.

Everything lives under one data directory so a restart (or a SIGKILL) loses nothing that was committed:

- ``scenes/<sha256>.glb`` or ``.rbscene``: uploaded scenes (glTF binaries or render-budget scene files),
  named by the hash of their bytes (never by a client name);
- ``service.sqlite3``: tables ``scenes``, ``jobs``, ``job_events`` (the ordered progress stream served
  as server-sent events) and ``stores`` (Pareto stores, keyed by the hash of their JSON);
- ``eval_cache.sqlite3``: the optimiser's evaluation cache (its own file, so its writes never wait on
  the job tables' and vice versa);
- ``tmp/``: uploads and previews in flight (emptied at start);
- ``references/<job id>/``: a queued or running job's camera references at display resolution, kept
  across its attempts so a resumed job reads them (removed when it ends, and at start for every job
  not re-queued).

Lifecycle: scenes, jobs and stores are listed newest first, a page at a time (:class:`Page`), and
deleted on request, never while something still needs them (a scene with queued or running jobs, a
running job: :class:`Conflict`); a finished job keeps only its last progress event.

Connections are per thread (SQLite objects must not cross threads); WAL lets the API read while the job
runner writes.

The package: :mod:`.records` (records, pages and cursors), :mod:`.schema` (file names and tables) and
:mod:`.database` (:class:`Storage`, the data directory itself).
"""

from __future__ import annotations

from .database import Storage
from .records import (
    JOB_STATES,
    SCENE_SUFFIXES,
    TERMINAL_STATES,
    Conflict,
    JobEvent,
    JobRecord,
    Page,
    SceneRecord,
    StoreRecord,
    decode_cursor,
    is_hex_id,
)
from .schema import DB_NAME, EVAL_CACHE_NAME, SCHEMA_VERSION, read_active_scene_hashes

__all__ = ["DB_NAME", "EVAL_CACHE_NAME", "JOB_STATES", "SCENE_SUFFIXES", "SCHEMA_VERSION", "TERMINAL_STATES",
           "Conflict", "JobEvent", "JobRecord", "Page", "SceneRecord", "Storage", "StoreRecord",
           "decode_cursor", "is_hex_id", "read_active_scene_hashes"]
