"""The service's data directory: content-addressed scene files and the SQLite tables (scenes, jobs and
their events, stores), with per-thread connections and one writer at a time."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
import threading
import time
import uuid
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

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
    encode_cursor,
    is_hex_id,
)
from .schema import ACTIVE_SCENE_HASHES, DB_NAME, EVAL_CACHE_NAME, SCHEMA, SCHEMA_VERSION


def _dumps(value: object) -> str:
    # allow_nan=False: a NaN that reached this far is a bug upstream; fail loudly rather than store it.
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


class Storage:
    """Scene files and the service tables in one data directory; safe to share between threads."""

    def __init__(self, data_dir: Path | str) -> None:
        self.data_dir = Path(data_dir).resolve()
        self.scenes_dir = self.data_dir / "scenes"
        self.tmp_dir = self.data_dir / "tmp"
        self.references_dir = self.data_dir / "references"
        self.db_path = self.data_dir / DB_NAME
        self.eval_cache_path = self.data_dir / EVAL_CACHE_NAME
        for d in (self.data_dir, self.scenes_dir, self.tmp_dir, self.references_dir):
            d.mkdir(parents=True, exist_ok=True)
        for leftover in self.tmp_dir.iterdir():  # half-written uploads from a killed process
            if leftover.is_dir():
                shutil.rmtree(leftover, ignore_errors=True)
            else:
                leftover.unlink(missing_ok=True)
        self._local = threading.local()
        self._all: list[sqlite3.Connection] = []
        self._all_lock = threading.Lock()
        # Serialises writers inside this process (SQLite would, too, but with busy waits).
        self._write_lock = threading.Lock()
        with self._write_lock:
            conn = self._connection()
            conn.executescript(SCHEMA)  # runs in its own transaction
            conn.execute(
                "INSERT OR IGNORE INTO meta(key, value) VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),)
            )

    # -- connections -------------------------------------------------------------------------------
    def _connection(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.db_path, timeout=30.0, isolation_level=None, check_same_thread=False)
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.execute("PRAGMA busy_timeout=30000")
            conn.execute("PRAGMA foreign_keys=ON")
            conn.row_factory = sqlite3.Row
            self._local.conn = conn
            with self._all_lock:
                self._all.append(conn)
        return conn

    @contextmanager
    def _conn(self) -> Iterator[sqlite3.Connection]:
        conn = self._connection()
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield conn
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        else:
            conn.execute("COMMIT")

    def close(self) -> None:
        """Close every connection this object opened (call once, at shutdown)."""
        with self._all_lock:
            for conn in self._all:
                try:
                    conn.close()
                except sqlite3.Error:
                    pass
            self._all.clear()
        self._local = threading.local()

    def journal_mode(self) -> str:
        return str(self._connection().execute("PRAGMA journal_mode").fetchone()[0])

    # -- scene files -------------------------------------------------------------------------------
    def new_temp_path(self, suffix: str = "") -> Path:
        """A fresh file name inside the data directory's tmp/ (nothing is created)."""
        return self.tmp_dir / f"{uuid.uuid4().hex}{suffix}"

    def scene_path(self, scene_id: str) -> Path:
        """The stored file of a scene (``.glb`` unless a scene file with that id is stored)."""
        if not is_hex_id(scene_id, 64):
            raise ValueError(f"scene id must be 64 lowercase hex characters, got {scene_id!r}")
        for suffix in SCENE_SUFFIXES[1:]:
            path = self.scenes_dir / f"{scene_id}{suffix}"
            if path.exists():
                return path
        return self.scenes_dir / f"{scene_id}{SCENE_SUFFIXES[0]}"

    def adopt_scene_file(self, *, temp_path: Path, scene_id: str, suffix: str = ".glb") -> Path:
        """Move a verified upload to its content address (a no-op if the same bytes are already there)."""
        if suffix not in SCENE_SUFFIXES:
            raise ValueError(f"scene file suffix must be one of {SCENE_SUFFIXES}, got {suffix!r}")
        target = self.scene_path(scene_id).with_suffix(suffix)  # scene_path validates the id
        if target.exists():
            temp_path.unlink(missing_ok=True)
        else:
            os.replace(temp_path, target)
        return target

    def add_scene(
        self, *, scene_id: str, size: int, content_hash: str, stats: dict[str, Any], inert: dict[str, str],
        cameras: int,
    ) -> SceneRecord:
        now = time.time()
        with self._write_lock, self._conn() as conn:
            conn.execute(
                "INSERT OR IGNORE INTO scenes(id, size, content_hash, stats, inert, cameras, created)"
                " VALUES (?, ?, ?, ?, ?, ?, ?)",
                (scene_id, size, content_hash, _dumps(stats), _dumps(inert), cameras, now),
            )
        record = self.get_scene(scene_id=scene_id)
        assert record is not None
        return record

    def get_scene(self, *, scene_id: str) -> SceneRecord | None:
        row = self._connection().execute("SELECT * FROM scenes WHERE id = ?", (scene_id,)).fetchone()
        return None if row is None else self._scene(row)

    def _page(self, table: str, limit: int, cursor: str | None, where: str = "",
              args: tuple[Any, ...] = (), columns: str = "*") -> tuple[list[sqlite3.Row], str | None]:
        """Rows of ``table`` newest first (keyset pagination on created, id: stable while rows come and
        go); ``where`` and ``args`` filter."""
        if not 1 <= limit <= 1000:
            raise ValueError("limit must be in 1..1000")
        clauses, params = ([where], list(args)) if where else ([], [])
        if cursor is not None:
            clauses.append("(created, id) < (?, ?)")
            params.extend(decode_cursor(cursor))
        sql = (f"SELECT {columns} FROM {table} {'WHERE ' + ' AND '.join(clauses) if clauses else ''} "
               "ORDER BY created DESC, id DESC LIMIT ?")
        rows = self._connection().execute(sql, (*params, limit + 1)).fetchall()
        more = len(rows) > limit
        rows = rows[:limit]
        return rows, (encode_cursor(rows[-1]["created"], rows[-1]["id"]) if more else None)

    @staticmethod
    def _scene(row: sqlite3.Row) -> SceneRecord:
        return SceneRecord(
            id=row["id"], size=row["size"], content_hash=row["content_hash"], stats=json.loads(row["stats"]),
            inert=json.loads(row["inert"]), cameras=row["cameras"], created=row["created"],
        )

    def list_scenes(self, *, limit: int = 100, cursor: str | None = None) -> Page[SceneRecord]:
        rows, nxt = self._page("scenes", limit, cursor)
        return Page([self._scene(r) for r in rows], nxt)

    def delete_scene(self, *, scene_id: str) -> bool:
        """Delete a scene, its file and its finished jobs (their stores stay: they are the results).
        False if there is no such scene; Conflict while one of its jobs is queued or running."""
        with self._write_lock, self._conn() as conn:
            if conn.execute("SELECT 1 FROM scenes WHERE id = ?", (scene_id,)).fetchone() is None:
                return False
            active = conn.execute("SELECT COUNT(*) FROM jobs WHERE scene_id = ? AND state IN ('queued', "
                                  "'running')", (scene_id,)).fetchone()[0]
            if active:
                raise Conflict(f"scene {scene_id!r} has {active} queued or running job(s); cancel them first")
            conn.execute("DELETE FROM job_events WHERE job_id IN (SELECT id FROM jobs WHERE scene_id = ?)",
                         (scene_id,))
            conn.execute("DELETE FROM jobs WHERE scene_id = ?", (scene_id,))
            conn.execute("DELETE FROM scenes WHERE id = ?", (scene_id,))
        self.scene_path(scene_id).unlink(missing_ok=True)  # after the commit: a crash leaves a stray file
        return True

    # -- jobs --------------------------------------------------------------------------------------
    def create_job(self, *, scene_id: str, spec: dict[str, Any]) -> JobRecord:
        """Queue a job; KeyError if the scene does not exist (or was deleted a moment ago)."""
        job_id = uuid.uuid4().hex
        now = time.time()
        with self._write_lock, self._conn() as conn:
            if conn.execute("SELECT 1 FROM scenes WHERE id = ?", (scene_id,)).fetchone() is None:
                raise KeyError(scene_id)
            conn.execute(
                "INSERT INTO jobs(id, scene_id, spec, state, created) VALUES (?, ?, ?, 'queued', ?)",
                (job_id, scene_id, _dumps(spec), now),
            )
            self._append_event(conn, job_id=job_id, kind="queued", data={"state": "queued"})
        record = self.get_job(job_id=job_id)
        assert record is not None
        return record

    @staticmethod
    def _job(row: sqlite3.Row) -> JobRecord:
        return JobRecord(
            id=row["id"], scene_id=row["scene_id"], spec_json=row["spec"], state=row["state"],
            progress=json.loads(row["progress"]), error=row["error"], store_id=row["store_id"],
            cancel_requested=bool(row["cancel_requested"]), attempts=row["attempts"], created=row["created"],
            started=row["started"], finished=row["finished"], elapsed_s=row["elapsed_s"],
        )

    def get_job(self, *, job_id: str) -> JobRecord | None:
        row = self._connection().execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return None if row is None else self._job(row)

    def list_jobs(self, *, states: tuple[str, ...] | None = None) -> list[JobRecord]:
        conn = self._connection()
        if states is None:
            rows = conn.execute("SELECT * FROM jobs ORDER BY created").fetchall()
        else:
            marks = ",".join("?" * len(states))
            rows = conn.execute(f"SELECT * FROM jobs WHERE state IN ({marks}) ORDER BY created",
                                states).fetchall()
        return [self._job(r) for r in rows]

    def page_jobs(self, *, limit: int = 100, cursor: str | None = None, state: str | None = None,
                  scene_id: str | None = None) -> Page[JobRecord]:
        clauses, args = [], []
        for column, value in (("state", state), ("scene_id", scene_id)):
            if value is not None:
                clauses.append(f"{column} = ?")
                args.append(value)
        rows, nxt = self._page("jobs", limit, cursor, " AND ".join(clauses), tuple(args))
        return Page([self._job(r) for r in rows], nxt)

    def delete_job(self, *, job_id: str) -> bool:
        """Delete a finished job and its events (its store stays). False if there is no such job;
        Conflict while it is queued or running."""
        with self._write_lock, self._conn() as conn:
            row = conn.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                return False
            if row["state"] not in TERMINAL_STATES:
                raise Conflict(f"job {job_id!r} is {row['state']}; cancel it first "
                               "(POST /jobs/{id}/cancel)")
            conn.execute("DELETE FROM job_events WHERE job_id = ?", (job_id,))
            conn.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
        return True

    def job_references(self, job_id: str) -> Path:
        """The folder of a job's camera references at display resolution: kept across its attempts (a
        job resumed after a restart reads them instead of rendering each camera's Max again, the costliest
        render of its pricing), removed when it ends (:meth:`drop_job_references`)."""
        if not is_hex_id(job_id, 32):
            raise ValueError(f"not a job id: {job_id!r}")
        return self.references_dir / job_id

    def drop_job_references(self, job_id: str) -> None:
        shutil.rmtree(self.job_references(job_id), ignore_errors=True)

    def prune_references(self, keep: Iterable[str]) -> None:
        """Remove every job's references but those of ``keep`` (the jobs a start re-queues): jobs that
        ended while no service ran, or were deleted, leave nothing behind."""
        kept = set(keep)
        for entry in self.references_dir.iterdir():
            if entry.name not in kept:
                if entry.is_dir():
                    shutil.rmtree(entry, ignore_errors=True)
                else:
                    entry.unlink(missing_ok=True)

    def active_scene_hashes(self) -> list[str]:
        """Content hashes of the scenes of queued or running jobs (their evaluations must be kept)."""
        return [r[0] for r in self._connection().execute(ACTIVE_SCENE_HASHES).fetchall()]

    def count_jobs(self) -> dict[str, int]:
        rows = self._connection().execute("SELECT state, COUNT(*) FROM jobs GROUP BY state").fetchall()
        counts = dict.fromkeys(JOB_STATES, 0)
        counts.update({r[0]: r[1] for r in rows})
        return counts

    def update_job(
        self, *, job_id: str, state: str | None = None, progress: dict[str, Any] | None = None,
        error: str | None = None, store_id: str | None = None, started: float | None = None,
        finished: float | None = None, elapsed_s: float | None = None, bump_attempts: bool = False,
        event: tuple[str, dict[str, Any]] | None = None,
    ) -> None:
        """Change some columns and (optionally) append one event, atomically."""
        sets: list[str] = []
        args: list[object] = []
        for column, value in (
            ("state", state), ("error", error), ("store_id", store_id), ("started", started),
            ("finished", finished), ("elapsed_s", elapsed_s),
        ):
            if value is not None:
                sets.append(f"{column} = ?")
                args.append(value)
        if progress is not None:
            sets.append("progress = ?")
            args.append(_dumps(progress))
        if bump_attempts:
            sets.append("attempts = attempts + 1")
        with self._write_lock, self._conn() as conn:
            if sets:
                conn.execute(f"UPDATE jobs SET {', '.join(sets)} WHERE id = ?", (*args, job_id))
            if event is not None:
                self._append_event(conn, job_id=job_id, kind=event[0], data=event[1])
            if state in TERMINAL_STATES:
                self._trim_events(conn, job_id)

    def claim_job(self, *, job_id: str) -> JobRecord | None:
        """Move a queued job to running (one attempt more) unless someone got there first (a cancel, another
        worker); returns the claimed record or None."""
        with self._write_lock, self._conn() as conn:
            cur = conn.execute(
                "UPDATE jobs SET state = 'running', started = ?, attempts = attempts + 1"
                " WHERE id = ? AND state = 'queued'", (time.time(), job_id),
            )
            if cur.rowcount != 1:
                return None
            attempts = conn.execute("SELECT attempts FROM jobs WHERE id = ?", (job_id,)).fetchone()[0]
            self._append_event(conn, job_id=job_id, kind="started",
                               data={"state": "running", "attempt": attempts})
        return self.get_job(job_id=job_id)

    def request_cancel(self, *, job_id: str) -> JobRecord | None:
        """Flag a job for cancellation; a queued job is cancelled at once. Returns the new record."""
        with self._write_lock, self._conn() as conn:
            row = conn.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                return None
            if row["state"] == "queued":
                conn.execute(
                    "UPDATE jobs SET state = 'cancelled', cancel_requested = 1, finished = ? WHERE id = ?",
                    (time.time(), job_id),
                )
                self._append_event(conn, job_id=job_id, kind="cancelled", data={"state": "cancelled"})
                self._trim_events(conn, job_id)
            elif row["state"] == "running":
                conn.execute("UPDATE jobs SET cancel_requested = 1 WHERE id = ?", (job_id,))
        return self.get_job(job_id=job_id)

    # -- events ------------------------------------------------------------------------------------
    @staticmethod
    def _append_event(conn: sqlite3.Connection, *, job_id: str, kind: str, data: dict[str, Any]) -> int:
        seq = conn.execute(
            "SELECT COALESCE(MAX(seq), 0) + 1 FROM job_events WHERE job_id = ?", (job_id,)
        ).fetchone()[0]
        conn.execute(
            "INSERT INTO job_events(job_id, seq, kind, data, created) VALUES (?, ?, ?, ?, ?)",
            (job_id, seq, kind, _dumps(data), time.time()),
        )
        return int(seq)

    @staticmethod
    def _trim_events(conn: sqlite3.Connection, job_id: str) -> None:
        """A finished job keeps its state changes and its last progress event (the log would otherwise
        hold one row per progress update forever); sequence numbers stay as they were."""
        conn.execute(
            "DELETE FROM job_events WHERE job_id = ? AND kind = 'progress' AND seq < "
            "(SELECT MAX(seq) FROM job_events WHERE job_id = ? AND kind = 'progress')", (job_id, job_id))

    def append_event(self, *, job_id: str, kind: str, data: dict[str, Any]) -> int:
        with self._write_lock, self._conn() as conn:
            return self._append_event(conn, job_id=job_id, kind=kind, data=data)

    def events_after(self, *, job_id: str, after_seq: int = 0, limit: int = 1000) -> list[JobEvent]:
        rows = self._connection().execute(
            "SELECT * FROM job_events WHERE job_id = ? AND seq > ? ORDER BY seq LIMIT ?",
            (job_id, after_seq, limit),
        ).fetchall()
        return [
            JobEvent(job_id=r["job_id"], seq=r["seq"], kind=r["kind"], data=json.loads(r["data"]),
                     created=r["created"])
            for r in rows
        ]

    # -- stores ------------------------------------------------------------------------------------
    def put_store(self, *, scene_id: str, job_id: str, body: str) -> str:
        """Keep a store's JSON under the hash of its bytes (equal stores share one id)."""
        store_id = hashlib.sha256(body.encode()).hexdigest()[:32]
        with self._write_lock, self._conn() as conn:
            conn.execute(
                "INSERT OR IGNORE INTO stores(id, scene_id, job_id, body, size, created)"
                " VALUES (?, ?, ?, ?, ?, ?)",
                (store_id, scene_id, job_id, body, len(body.encode()), time.time()),
            )
        return store_id

    @staticmethod
    def _store(row: sqlite3.Row) -> StoreRecord:
        return StoreRecord(id=row["id"], scene_id=row["scene_id"], job_id=row["job_id"],
                           body=row["body"] if "body" in row.keys() else "", size=row["size"],
                           created=row["created"])

    def get_store(self, *, store_id: str) -> StoreRecord | None:
        row = self._connection().execute("SELECT * FROM stores WHERE id = ?", (store_id,)).fetchone()
        return None if row is None else self._store(row)

    def list_stores(self, *, limit: int = 100, cursor: str | None = None,
                    scene_id: str | None = None) -> Page[StoreRecord]:
        """Stores without their bodies (``body`` is empty: fetch one with :meth:`get_store`)."""
        where, args = ("scene_id = ?", (scene_id,)) if scene_id is not None else ("", ())
        rows, nxt = self._page("stores", limit, cursor, where, args,
                               columns="id, scene_id, job_id, size, created")
        return Page([self._store(r) for r in rows], nxt)

    def delete_store(self, *, store_id: str) -> bool:
        """Delete a store (jobs that made it keep its id, and answer 404 for it from then on)."""
        with self._write_lock, self._conn() as conn:
            return conn.execute("DELETE FROM stores WHERE id = ?", (store_id,)).rowcount == 1
