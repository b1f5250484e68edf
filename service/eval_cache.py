"""Persistent evaluation cache (SQLite): a repeated or resumed run never renders the same thing twice.

Key: scene content hash, camera key, packed settings, metric (with the evaluation-pipeline version),
hardware profile, fps and resolution. Values: error, power, frame time and the energy breakdown.
The file uses WAL mode so a reader (the REST service) and a writer (a job) can share it, and every
batch is one transaction, so a killed process loses at most the batch in flight.
"""

from __future__ import annotations

import json
import math
import sqlite3
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


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
    PRIMARY KEY (scene, camera, packed, metric, profile, width, height, fps)
) WITHOUT ROWID;
"""


class EvalCache:
    """SQLite-backed map from (CacheKey, packed settings) to :class:`Evaluation`; thread-safe.

    ``path=None`` keeps the cache in memory (tests, one-off runs)."""

    def __init__(self, path: str | Path | None = None) -> None:
        self.path = None if path is None else Path(path)
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
        self.hits = 0
        self.misses = 0

    def get_many(self, key: CacheKey, packed: Sequence[int]) -> dict[int, Evaluation]:
        """Cached evaluations among ``packed`` (missing ones are absent from the result)."""
        out: dict[int, Evaluation] = {}
        wanted = list(dict.fromkeys(int(p) for p in packed))
        with self._lock:
            for start in range(0, len(wanted), 500):
                chunk = wanted[start:start + 500]
                q = ("SELECT packed, error, power_w, frame_time_s, breakdown FROM evaluations "
                     "WHERE scene=? AND camera=? AND metric=? AND profile=? AND width=? AND height=? "
                     "AND fps=? AND packed IN ("
                     + ",".join("?" * len(chunk)) + ")")
                rows = self._db.execute(q, (key.scene, key.camera, key.metric, key.profile, key.width,
                                            key.height, float(key.fps), *chunk)).fetchall()
                for p, e, pw, ft, bd in rows:
                    out[int(p)] = Evaluation(e, pw, ft, json.loads(bd))
            self.hits += len(out)
            self.misses += len(wanted) - len(out)
        return out

    def put_many(self, key: CacheKey, items: Iterable[tuple[int, Evaluation]]) -> None:
        """Store evaluations in one transaction (existing entries are kept)."""
        rows = [(key.scene, key.camera, int(p), key.metric, key.profile, key.width, key.height,
                 float(key.fps), ev.error, ev.power_w, ev.frame_time_s,
                 json.dumps(ev.breakdown, sort_keys=True))
                for p, ev in items]
        if not rows:
            return
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                self._db.executemany(
                    "INSERT OR IGNORE INTO evaluations VALUES (?,?,?,?,?,?,?,?,?,?,?,?)", rows)
                self._db.execute("COMMIT")
            except BaseException:
                self._db.execute("ROLLBACK")
                raise

    def __bool__(self) -> bool:
        return True  # a cache is a cache even while empty (``cache or default`` must not replace it)

    def __len__(self) -> int:
        with self._lock:
            return int(self._db.execute("SELECT COUNT(*) FROM evaluations").fetchone()[0])

    def stats(self) -> dict[str, Any]:
        return {"entries": len(self), "hits": self.hits, "misses": self.misses,
                "path": None if self.path is None else str(self.path)}

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def __enter__(self) -> EvalCache:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
