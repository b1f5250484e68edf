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
