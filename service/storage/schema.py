"""The service database's file names and tables, and the one query another process may run on it while
a service is using it (read-only)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

SCHEMA_VERSION = 1
DB_NAME = "service.sqlite3"
EVAL_CACHE_NAME = "eval_cache.sqlite3"

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS scenes (
    id TEXT PRIMARY KEY,
    size INTEGER NOT NULL,
    content_hash TEXT NOT NULL,
    stats TEXT NOT NULL,
    inert TEXT NOT NULL,
    cameras INTEGER NOT NULL,
    created REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    scene_id TEXT NOT NULL REFERENCES scenes(id),
    spec TEXT NOT NULL,
    state TEXT NOT NULL,
    progress TEXT NOT NULL DEFAULT '{}',
    error TEXT,
    store_id TEXT,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    attempts INTEGER NOT NULL DEFAULT 0,
    created REAL NOT NULL,
    started REAL,
    finished REAL,
    elapsed_s REAL NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state);
CREATE INDEX IF NOT EXISTS jobs_scene ON jobs(scene_id);
CREATE INDEX IF NOT EXISTS jobs_created ON jobs(created, id);
CREATE INDEX IF NOT EXISTS scenes_created ON scenes(created, id);
CREATE TABLE IF NOT EXISTS job_events (
    job_id TEXT NOT NULL REFERENCES jobs(id),
    seq INTEGER NOT NULL,
    kind TEXT NOT NULL,
    data TEXT NOT NULL,
    created REAL NOT NULL,
    PRIMARY KEY (job_id, seq)
);
CREATE TABLE IF NOT EXISTS stores (
    id TEXT PRIMARY KEY,
    scene_id TEXT NOT NULL,
    job_id TEXT NOT NULL,
    body TEXT NOT NULL,
    size INTEGER NOT NULL,
    created REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS stores_created ON stores(created, id);
"""


ACTIVE_SCENE_HASHES = ("SELECT DISTINCT s.content_hash FROM jobs j JOIN scenes s ON s.id = j.scene_id "
                        "WHERE j.state IN ('queued', 'running')")


def read_active_scene_hashes(data_dir: Path) -> list[str]:
    """:meth:`Storage.active_scene_hashes` of a data directory a service may be using right now, read
    without side effects (opening a :class:`Storage` would empty its tmp/)."""
    path = Path(data_dir) / DB_NAME
    if not path.is_file():
        return []
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=30.0)
    try:
        return [r[0] for r in conn.execute(ACTIVE_SCENE_HASHES).fetchall()]
    finally:
        conn.close()
