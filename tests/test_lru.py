"""service.lru.LRUCache: the one LRU of the service."""

from __future__ import annotations

import threading

import pytest
from hypothesis import given
from hypothesis import strategies as st

from service.lru import LRUCache


@given(capacity=st.integers(1, 6), ops=st.lists(st.tuples(st.booleans(), st.integers(0, 9)), max_size=60))
def test_behaves_like_a_reference_lru(capacity: int, ops: list[tuple[bool, int]]) -> None:
    cache: LRUCache[int, int] = LRUCache(capacity)
    model: list[int] = []  # keys, oldest first
    for is_put, key in ops:
        if is_put:
            cache.put(key, key * 10)
            if key in model:
                model.remove(key)
            model.append(key)
            del model[:-capacity]
        else:
            got = cache.get(key)
            assert got == (key * 10 if key in model else None)
            if key in model:
                model.remove(key)
                model.append(key)
        assert list(cache) == model and len(cache) == len(model)


def test_rejects_no_capacity_and_is_safe_across_threads() -> None:
    with pytest.raises(ValueError):
        LRUCache(0)
    cache: LRUCache[int, int] = LRUCache(50)

    def work(offset: int) -> None:
        for i in range(2000):
            cache.put((i + offset) % 200, i)
            cache.get(i % 200)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(cache) == 50 and all(key in cache for key in cache)


@given(sizes=st.lists(st.tuples(st.integers(0, 5), st.integers(1, 40)), max_size=40))
def test_weighted_cache_keeps_under_its_weight_and_the_newest_entry(sizes: list[tuple[int, int]]) -> None:
    cache: LRUCache[int, bytes] = LRUCache(4, weigh=len, max_weight=50)
    for key, size in sizes:
        cache.put(key, b"x" * size)
        held = [cache._items[k] for k in cache]
        assert cache.weight == sum(map(len, held))
        assert cache.weight <= 50 or len(held) == 1  # one entry over the limit is kept: the newest
        assert cache.get(key) == b"x" * size and len(held) <= 4
    cache.clear()
    assert cache.weight == 0 and len(cache) == 0
    with pytest.raises(ValueError):
        LRUCache(3, weigh=len)
