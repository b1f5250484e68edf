"""Set-associative LRU cache model of the T&I unit: textbook cases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim_core import _core


def _sweep(start: int, stop: int, step: int) -> np.ndarray:
    return np.arange(start, stop, step, dtype=np.uint64)


def test_working_set_that_fits_hits_after_warm_up() -> None:
    c = _core.CacheModel(_core.CacheConfig(32768, 64, 4))
    lines = _sweep(0, 16384, 64)
    c.access_many(lines, 64)
    assert c.misses == lines.size  # compulsory misses only
    for _ in range(3):
        c.access_many(lines, 64)
    assert c.accesses == 4 * lines.size and c.misses == lines.size
    assert c.dram_bytes == lines.size * 64


def test_streaming_pattern_larger_than_cache_always_misses() -> None:
    c = _core.CacheModel(_core.CacheConfig(32768, 64, 4))
    stream = _sweep(0, 2 * 32768, 64)
    for _ in range(3):
        c.access_many(stream, 64)
    assert c.misses == c.accesses == 3 * stream.size


@pytest.mark.parametrize("ways,expected_misses", [(1, 20), (2, 2)])
def test_conflict_misses_depend_on_associativity(ways: int, expected_misses: int) -> None:
    size = 4096
    c = _core.CacheModel(_core.CacheConfig(size, 64, ways))
    stride = size // ways  # same set index
    for _ in range(10):
        c.access(0, 4)
        c.access(stride, 4)
    assert c.misses == expected_misses


def test_lru_victim_is_least_recently_used() -> None:
    c = _core.CacheModel(_core.CacheConfig(256, 64, 2))  # 2 sets: 0, 128, 256 share set 0
    for a in (0, 128, 0, 256):
        c.access(a, 1)
    assert c.misses == 3
    c.access(0, 1)
    assert c.misses == 3
    c.access(128, 1)
    assert c.misses == 4


def test_straddling_fetch_and_disabled_cache() -> None:
    c = _core.CacheModel(_core.CacheConfig(1024, 64, 2))
    c.access(60, 8)
    assert (c.accesses, c.misses) == (2, 2)
    off = _core.CacheModel(_core.CacheConfig(0, 64, 4))
    off.access(0, 40)
    off.access(0, 40)
    assert off.misses == 2 and off.dram_bytes == 128  # 32-byte bursts, no reuse


def test_bad_geometry_is_rejected() -> None:
    for args in ((3000, 64, 4), (4096, 48, 4), (4096, 64, 3), (128, 64, 4)):
        with pytest.raises(ValueError):
            _core.CacheConfig(*args)


def _reference_lru_misses(addresses: list[int], nbytes: int, size: int, line: int, ways: int) -> list[int]:
    """Textbook set-associative LRU (one ordered list per set): the miss count after every access."""
    sets: dict[int, list[int]] = {}
    nsets = size // (line * ways)
    misses, out = 0, []
    for a in addresses:
        for ln in range(a // line, (a + nbytes - 1) // line + 1):
            s = sets.setdefault(ln % nsets, [])
            if ln in s:
                s.remove(ln)
            else:
                misses += 1
                if len(s) == ways:
                    s.pop(0)
            s.append(ln)
        out.append(misses)
    return out


@settings(max_examples=60, deadline=None)
@given(
    geometry=st.sampled_from([(256, 64, 2), (1024, 64, 4), (4096, 64, 1), (2048, 128, 4), (512, 32, 8)]),
    lines=st.lists(st.integers(0, 63), min_size=1, max_size=300),
    offset=st.integers(0, 127),
    nbytes=st.sampled_from([1, 32, 48, 64, 128]),
)
def test_model_equals_textbook_lru(geometry: tuple[int, int, int], lines: list[int], offset: int,
                                   nbytes: int) -> None:
    # Repeated lines (the model's shortcut for the previous line) and straddling fetches included.
    size, line, ways = geometry
    addresses = [ln * 48 + offset for ln in lines]
    c = _core.CacheModel(_core.CacheConfig(size, line, ways))
    got = []
    for a in addresses:
        c.access(a, nbytes)
        got.append(c.misses)
    assert got == _reference_lru_misses(addresses, nbytes, size, line, ways)
    assert c.dram_bytes == c.misses * line
