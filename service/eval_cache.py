"""Persistent evaluation cache (SQLite): a repeated or resumed run never renders the same thing twice.

Key: scene content hash, camera key, packed settings, metric (with the evaluation-pipeline version),
hardware profile (its name and a digest of its figures, so an edited profile is priced afresh), fps and
resolution. Values: error, power, frame time and the energy breakdown.
The file uses WAL mode so a reader (the REST service) and a writer (a job) can share it, and every
batch is one transaction, so a killed process loses at most the batch in flight.

Size: the cache holds at most ``max_bytes`` (default 2 GiB) of pages in use. Past that, the least
recently used cameras go first, whole (a camera's evaluations are contiguous in the file, so deleting
them frees whole pages) until the cache is back under 90 % of the cap; evaluations of the scenes
``protected()`` names (those of jobs still queued or running) are never evicted. ``prune`` does the same
on demand and then VACUUMs, so the file itself shrinks.
"""

from __future__ import annotations

import json
import math
import sqlite3
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

DEFAULT_MAX_BYTES = 2 * 1024**3
#: After an eviction the cache holds at most this fraction of its cap (so evictions come in batches).
LOW_WATER = 0.9


@dataclass(frozen=True)
class Evaluation:
    """Error (1 - SSIM, or the chosen metric's error), power at the target fps, frame time, breakdown."""

    error: float
    power_w: float
    frame_time_s: float
    breakdown: dict[str, float] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        for name in ("error", "power_w", "frame_time_s"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"evaluation {name} must be finite, got {v}")


@dataclass(frozen=True)
class CacheKey:
    """Everything an evaluation depends on besides the packed settings."""

    scene: str
    camera: str
    metric: str
    profile: str
    width: int
    height: int
    fps: float


_SCHEMA = """
CREATE TABLE IF NOT EXISTS evaluations (
    scene TEXT NOT NULL, camera TEXT NOT NULL, packed INTEGER NOT NULL, metric TEXT NOT NULL,
    profile TEXT NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL, fps REAL NOT NULL,
    error REAL NOT NULL, power_w REAL NOT NULL, frame_time_s REAL NOT NULL, breakdown TEXT NOT NULL,
    used REAL NOT NULL DEFAULT 0,
    PRIMARY KEY (scene, camera, packed, metric, profile, width, height, fps)
) WITHOUT ROWID;
"""
_KEY_WHERE = "scene=? AND camera=? AND metric=? AND profile=? AND width=? AND height=? AND fps=?"


class EvalCache:
    """SQLite-backed map from (CacheKey, packed settings) to :class:`Evaluation`; thread-safe.

    ``path=None`` keeps the cache in memory (tests, one-off runs). ``max_bytes=None``: no cap.
    ``protected`` returns the scene content hashes whose evaluations eviction must keep."""

    def __init__(self, path: str | Path | None = None, *, max_bytes: int | None = DEFAULT_MAX_BYTES,
                 protected: Callable[[], Iterable[str]] | None = None) -> None:
        if max_bytes is not None and max_bytes <= 0:
            raise ValueError(f"max_bytes must be positive, got {max_bytes}")
        self.path = None if path is None else Path(path)
        self.max_bytes = max_bytes
        self.protected = protected or (lambda: ())
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(":memory:" if self.path is None else str(self.path), timeout=30.0,
                                   check_same_thread=False, isolation_level=None)
        self._lock = threading.Lock()
        with self._lock:
            if self.path is not None:
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.executescript(_SCHEMA)
            columns = {row[1] for row in self._db.execute("PRAGMA table_info(evaluations)")}
            if "used" not in columns:  # a cache written before eviction existed: all equally old
                self._db.execute("ALTER TABLE evaluations ADD COLUMN used REAL NOT NULL DEFAULT 0")
        self.hits = 0
        self.misses = 0
        self.evicted = 0

    def get_many(self, key: CacheKey, packed: Sequence[int]) -> dict[int, Evaluation]:
        """Cached evaluations among ``packed`` (missing ones are absent from the result)."""
        out: dict[int, Evaluation] = {}
        wanted = list(dict.fromkeys(int(p) for p in packed))
        key_args = (key.scene, key.camera, key.metric, key.profile, key.width, key.height, float(key.fps))
        with self._lock:
            for start in range(0, len(wanted), 500):
                chunk = wanted[start:start + 500]
                marks = ",".join("?" * len(chunk))
                q = ("SELECT packed, error, power_w, frame_time_s, breakdown FROM evaluations "
                     f"WHERE {_KEY_WHERE} AND packed IN ({marks})")
                rows = self._db.execute(q, (*key_args, *chunk)).fetchall()
                for p, e, pw, ft, bd in rows:
                    out[int(p)] = Evaluation(e, pw, ft, json.loads(bd))
                if rows:  # recently used: the last to be evicted
                    self._db.execute(
                        f"UPDATE evaluations SET used=? WHERE {_KEY_WHERE} AND packed IN ({marks})",
                        (time.time(), *key_args, *chunk))
            self.hits += len(out)
            self.misses += len(wanted) - len(out)
        return out

    def count_missing(self, key: CacheKey, packed: Sequence[int]) -> int:
        """How many of ``packed`` (distinct) the cache does not hold, without reading them (no hit or
        miss counted, nothing marked used): what a job's time left needs to know before it renders."""
        wanted = list(dict.fromkeys(int(p) for p in packed))
        key_args = (key.scene, key.camera, key.metric, key.profile, key.width, key.height, float(key.fps))
        held = 0
        with self._lock:
            for start in range(0, len(wanted), 500):
                chunk = wanted[start:start + 500]
                q = (f"SELECT COUNT(*) FROM evaluations WHERE {_KEY_WHERE} AND packed IN "
                     f"({','.join('?' * len(chunk))})")
                held += int(self._db.execute(q, (*key_args, *chunk)).fetchone()[0])
        return len(wanted) - held

    def put_many(self, key: CacheKey, items: Iterable[tuple[int, Evaluation]]) -> None:
        """Store evaluations in one transaction (existing entries are kept)."""
        now = time.time()
        rows = [(key.scene, key.camera, int(p), key.metric, key.profile, key.width, key.height,
                 float(key.fps), ev.error, ev.power_w, ev.frame_time_s,
                 json.dumps(ev.breakdown, sort_keys=True), now)
                for p, ev in items]
        if not rows:
            return
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                self._db.executemany(
                    "INSERT OR IGNORE INTO evaluations VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)", rows)
                self._db.execute("COMMIT")
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            if self.max_bytes is not None and self._size_bytes() > self.max_bytes:
                self._evict(int(self.max_bytes * LOW_WATER))

    # -- size ----------------------------------------------------------------------------------------
    def _size_bytes(self) -> int:
        """Bytes of the pages in use (free pages inside the file are reused before it grows)."""
        page_size = self._db.execute("PRAGMA page_size").fetchone()[0]
        pages = self._db.execute("PRAGMA page_count").fetchone()[0]
        free = self._db.execute("PRAGMA freelist_count").fetchone()[0]
        return int((pages - free) * page_size)

    def size_bytes(self) -> int:
        with self._lock:
            return self._size_bytes()

    def _evict(self, target_bytes: int) -> int:
        """Delete the least recently used cameras (whole) of unprotected scenes until at most
        ``target_bytes`` are in use or nothing evictable is left; returns the evaluations deleted."""
        keep = sorted(set(self.protected()))
        deleted = 0
        while (size := self._size_bytes()) > target_bytes:
            total = int(self._db.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0])
            if total == 0:
                break
            per_row = size / total
            groups = self._db.execute(
                "SELECT scene, camera, COUNT(*) FROM evaluations "
                f"WHERE scene NOT IN ({','.join('?' * len(keep))}) "
                "GROUP BY scene, camera ORDER BY MAX(used), scene, camera", keep).fetchall()
            chosen, freed = [], 0.0
            for scene, camera, count in groups:
                chosen.append((scene, camera))
                freed += count * per_row
                if freed >= size - target_bytes:
                    break
            if not chosen:
                break  # everything left belongs to protected scenes
            self._db.execute("BEGIN IMMEDIATE")
            try:
                for start in range(0, len(chosen), 400):
                    part = chosen[start:start + 400]
                    cur = self._db.execute(
                        "DELETE FROM evaluations WHERE (scene, camera) IN "
                        f"(VALUES {','.join(['(?, ?)'] * len(part))})", [v for g in part for v in g])
                    deleted += cur.rowcount
                self._db.execute("COMMIT")
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
        self.evicted += deleted
        return deleted

    def prune(self, max_bytes: int | None = None) -> int:
        """Evict down to ``max_bytes`` (default: this cache's cap) and VACUUM, so the file shrinks too;
        returns the evaluations deleted."""
        cap = self.max_bytes if max_bytes is None else max_bytes
        with self._lock:
            deleted = self._evict(cap) if cap is not None else 0
            self._db.execute("VACUUM")
            return deleted

    def __bool__(self) -> bool:
        return True  # a cache is a cache even while empty (``cache or default`` must not replace it)

    def __len__(self) -> int:
        with self._lock:
            return int(self._db.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0])

    def stats(self) -> dict[str, Any]:
        """Size and use: entries, scenes and cameras held, bytes in use and on disk, the cap, the oldest
        and newest use (Unix time), and this object's hits, misses and evictions."""
        with self._lock:
            entries, scenes, cameras, oldest, newest = self._db.execute(
                "SELECT COUNT(*), COUNT(DISTINCT scene), COUNT(DISTINCT scene || char(0) || camera), "
                "MIN(used), MAX(used) FROM evaluations").fetchone()
            size = self._size_bytes()
        file_bytes = None
        if self.path is not None:
            file_bytes = sum(p.stat().st_size for p in (self.path, Path(f"{self.path}-wal")) if p.exists())
        return {"entries": int(entries), "scenes": int(scenes), "cameras": int(cameras), "size_bytes": size,
                "file_bytes": file_bytes, "max_bytes": self.max_bytes, "oldest_use": oldest,
                "newest_use": newest, "hits": self.hits, "misses": self.misses, "evicted": self.evicted,
                "path": None if self.path is None else str(self.path)}

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def __enter__(self) -> EvalCache:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
