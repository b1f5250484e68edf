"""The reports' share intervals against scipy's Wilson interval, and their edges."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.stats import binomtest

from service.stats import share_interval, share_text


@given(st.integers(1, 400).flatmap(lambda n: st.tuples(st.integers(0, n), st.just(n))))
def test_the_share_interval_is_scipys_wilson_interval(case: tuple[int, int]) -> None:
    hits, n = case
    lo, hi = share_interval(hits, n)
    ref = binomtest(hits, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert lo == pytest.approx(ref.low, abs=1e-12) and hi == pytest.approx(ref.high, abs=1e-12)
    assert 0.0 <= lo <= hits / n <= hi <= 1.0
    assert (lo == 0.0) == (hits == 0) and (hi == 1.0) == (hits == n)


def test_a_small_sample_cannot_tell_92_from_95_percent() -> None:
    """The main job's 12 frames: one miss is 92 %, yet 95 % lies well inside the interval; 45 of 45
    rules out less than 92 %."""
    lo, hi = share_interval(11, 12)
    assert lo < 0.95 < hi
    assert share_text(11, 12) == "11/12 (92 %; 95 % interval 65-99 %)"
    assert share_interval(45, 45)[0] > 0.92 and share_text(45, 45).endswith("interval 92-100 %)")


@pytest.mark.parametrize("hits, n", [(-1, 3), (4, 3), (0, 0), (1.5, 3), (True, 3), (1, math.nan),
                                     (1, math.inf), (2.0, 3)])
def test_bad_counts_are_refused(hits, n) -> None:
    with pytest.raises(ValueError):
        share_interval(hits, n)
