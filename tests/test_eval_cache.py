"""Evaluation cache: persistence across connections, key separation, bad values."""

from __future__ import annotations

import math
import threading

import pytest

from service.eval_cache import CacheKey, EvalCache, Evaluation


def _key(**kw) -> CacheKey:
    base = dict(scene="abc", camera="cam0", metric="ssim-v1", profile="mobile", width=32, height=24, fps=30.0)
    base.update(kw)
    return CacheKey(**base)


def test_persists_and_counts(tmp_path) -> None:
    path = tmp_path / "sub" / "cache.sqlite"
    with EvalCache(path) as c:
        c.put_many(_key(), [(1, Evaluation(0.1, 2.0, 0.01, {"rt": 1.5})), (7, Evaluation(0.0, 3.0, 0.02))])
        assert len(c) == 2
    with EvalCache(path) as c:
        got = c.get_many(_key(), [1, 7, 9, 1])
        assert set(got) == {1, 7}
        assert got[1] == Evaluation(0.1, 2.0, 0.01) and got[1].breakdown == {"rt": 1.5}
        assert (c.hits, c.misses) == (2, 1)
        # existing entries are kept, not overwritten
        c.put_many(_key(), [(1, Evaluation(0.9, 9.0, 0.9))])
        assert c.get_many(_key(), [1])[1].error == 0.1
        # what is missing, counted without reading (no hit or miss counted), each setting once
        hits = (c.hits, c.misses)
        assert c.count_missing(_key(), [1, 7, 9, 1, 9]) == 1 and c.count_missing(_key(), []) == 0
        assert c.count_missing(_key(camera="cam1"), [1, 7]) == 2
        assert c.count_missing(_key(), list(range(1200))) == 1198  # (beyond one query's 500)
        assert (c.hits, c.misses) == hits


@pytest.mark.parametrize("field,value", [
    ("scene", "x"), ("camera", "cam1"), ("metric", "psnr"), ("profile", "desktop"), ("width", 64),
    ("height", 48), ("fps", 60.0)])
def test_every_key_part_separates(field: str, value) -> None:
    c = EvalCache()
    assert c and len(c) == 0
    c.put_many(_key(), [(5, Evaluation(0.2, 1.0, 0.1))])
    assert c.get_many(_key(**{field: value}), [5]) == {}
    assert 5 in c.get_many(_key(), [5])


def test_many_keys_and_threads() -> None:
    c = EvalCache()

    def work(off: int) -> None:
        c.put_many(_key(), [(off * 1000 + i, Evaluation(i / 1000, float(i), 0.0)) for i in range(600)])

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(c) == 2400
    assert len(c.get_many(_key(), list(range(3000, 3600)))) == 600


def test_evaluation_rejects_non_finite() -> None:
    with pytest.raises(ValueError):
        Evaluation(math.nan, 1.0, 0.0)
    with pytest.raises(ValueError):
        Evaluation(0.0, math.inf, 0.0)


def _fill(c: EvalCache, scene: str, cameras: range, per_camera: int = 40) -> None:
    pad = {"pad": "x" * 400}  # realistic breakdown sizes make pages fill
    for k in cameras:
        c.put_many(_key(scene=scene, camera=f"cam{k}"),
                   [(p, Evaluation(0.1, 1.0, 0.01, pad)) for p in range(per_camera)])


def test_size_cap_evicts_least_recently_used_cameras_whole(tmp_path) -> None:
    cap = 400_000
    with EvalCache(tmp_path / "c.sqlite", max_bytes=cap) as c:
        _fill(c, "old", range(10))
        assert len(c.get_many(_key(scene="old", camera="cam0"), range(40))) == 40  # cam0 used again
        k = 0
        while c.evicted == 0:  # new cameras until the cap is first reached
            _fill(c, "new", range(k, k + 1))
            k += 1
        kept = {i for i in range(10) if c.get_many(_key(scene="old", camera=f"cam{i}"), [0])}
        assert 0 in kept and 1 not in kept  # cam1 was stored after cam0 but used less recently
        assert c.size_bytes() <= 0.9 * cap
        _fill(c, "new", range(k, k + 40))
        assert c.size_bytes() <= cap
        # A camera is kept or evicted whole, never in part; the newest are kept.
        for i in range(k + 40):
            assert len(c.get_many(_key(scene="new", camera=f"cam{i}"), range(40))) in (0, 40)
        assert c.get_many(_key(scene="new", camera=f"cam{k + 39}"), [5])


def test_protected_scenes_are_never_evicted(tmp_path) -> None:
    active = {"running-job-scene"}
    with EvalCache(tmp_path / "c.sqlite", max_bytes=300_000, protected=lambda: active) as c:
        _fill(c, "running-job-scene", range(8))
        _fill(c, "finished", range(40))
        for k in range(8):
            assert len(c.get_many(_key(scene="running-job-scene", camera=f"cam{k}"), range(40))) == 40
        assert c.evicted > 0
        active.clear()
        _fill(c, "finished", range(40, 60))
        assert c.size_bytes() <= 300_000


def test_prune_and_stats(tmp_path) -> None:
    path = tmp_path / "c.sqlite"
    with EvalCache(path, max_bytes=None) as c:
        _fill(c, "s", range(30))
        before = c.stats()
        assert before["entries"] == 1200 and before["scenes"] == 1 and before["cameras"] == 30
        assert before["size_bytes"] > 400_000 and before["file_bytes"] >= before["size_bytes"]
        deleted = c.prune(200_000)
        after = c.stats()
    assert 0 < deleted < 1200 and after["entries"] == 1200 - deleted and after["size_bytes"] <= 200_000
    assert path.stat().st_size < before["size_bytes"]  # VACUUM gave the space back


def test_a_cache_from_before_eviction_is_upgraded(tmp_path) -> None:
    import sqlite3

    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    db.executescript("""CREATE TABLE evaluations (
        scene TEXT NOT NULL, camera TEXT NOT NULL, packed INTEGER NOT NULL, metric TEXT NOT NULL,
        profile TEXT NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL, fps REAL NOT NULL,
        error REAL NOT NULL, power_w REAL NOT NULL, frame_time_s REAL NOT NULL, breakdown TEXT NOT NULL,
        PRIMARY KEY (scene, camera, packed, metric, profile, width, height, fps)) WITHOUT ROWID;
        INSERT INTO evaluations VALUES
            ('abc', 'cam0', 3, 'ssim-v1', 'mobile', 32, 24, 30.0, 0.5, 2.0, 0.1, '{}');""")
    db.commit()
    db.close()
    with EvalCache(path) as c:
        assert c.get_many(_key(), [3])[3] == Evaluation(0.5, 2.0, 0.1)
        c.put_many(_key(), [(4, Evaluation(0.4, 2.5, 0.1))])
        assert len(c) == 2
