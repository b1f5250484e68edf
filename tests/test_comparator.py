"""Compute-on-demand comparator (thesis ch. 4): chain lengths and their pricing with Table 4.1."""

from __future__ import annotations

import numpy as np
import pytest
from sim_core.energy import COMPARATOR_TABLE, comparator_stats

from sim_core import _core


def _from_bits(u: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(u.astype(np.uint32)).view(np.float32)


def test_chain_length_exact_cases() -> None:
    a = np.array([1.0, 1.0, 1.0, 1.0, 3.0], dtype=np.float32)
    b = np.array([1.0, 2.0, 1.5, np.inf, np.inf], dtype=np.float32)
    np.testing.assert_array_equal(_core.comparator_chain_lengths(a, b), [24, 0, 8, 0, 1])
    # The lowest 7 mantissa bits lie below the 24-bit comparator.
    lo = _from_bits(np.array([0x3F800000, 0x3F800000], dtype=np.uint32))
    hi = _from_bits(np.array([0x3F80007F, 0x3F800080], dtype=np.uint32))
    np.testing.assert_array_equal(_core.comparator_chain_lengths(lo, hi), [24, 23])


def test_chain_length_distribution_on_random_operands_is_analytic() -> None:
    """Each further bit is needed with probability 1/2: P(chain >= k) = 2^-k (Yun et al., via the thesis)."""
    rng = np.random.default_rng(0)
    n = 400_000
    a = _from_bits(rng.integers(0, 2**31, size=n, dtype=np.uint64))
    b = _from_bits(rng.integers(0, 2**31, size=n, dtype=np.uint64))
    finite = np.isfinite(a) & np.isfinite(b)  # drop NaN bit patterns (exponent all ones)
    c = _core.comparator_chain_lengths(np.ascontiguousarray(a[finite]), np.ascontiguousarray(b[finite]))
    m = c.size
    for k in range(0, 12):
        p = 2.0**-k
        got = float((c >= k).mean())
        assert abs(got - p) < 5 * np.sqrt(p * (1 - p) / m) + 1e-12, (k, got, p)
    # The mean of a geometric law with p = 1/2, truncated at 24 bits, is ~1 (bits after the first).
    assert abs(c.mean() - 1.0) < 0.01


def test_rejects_negative_or_nan_operands() -> None:
    with pytest.raises(ValueError):
        _core.comparator_chain_lengths(np.array([-1.0], np.float32), np.array([1.0], np.float32))
    with pytest.raises(ValueError):
        _core.comparator_chain_lengths(np.array([np.nan], np.float32), np.array([1.0], np.float32))
    with pytest.raises(ValueError):
        _core.comparator_chain_lengths(np.zeros(2, np.float32), np.zeros(3, np.float32))


def test_pricing_reproduces_table_rows_and_thesis_ratio() -> None:
    # One comparison at each tabulated chain length costs exactly that row.
    for k, _sd, se, _ad, ae in COMPARATOR_TABLE:
        h = np.zeros(25, dtype=np.int64)
        h[k] = 1
        s = comparator_stats(h)
        assert s.sync_energy_j == pytest.approx(se * 1e-12)
        assert s.async_energy_j == pytest.approx(ae * 1e-12)
    # Equal operands (24) are priced like the longest measured chain (23).
    h = np.zeros(25, dtype=np.int64)
    h[24] = 3
    assert comparator_stats(h).async_energy_j == pytest.approx(3 * 12.89e-12)
    # A z-test-like distribution around 7.3 bits: about 1/4 of the synchronous energy (thesis sec. 4.2.3).
    rng = np.random.default_rng(1)
    chains = np.clip(np.rint(rng.normal(7.3, 1.8, size=100_000)), 0, 24).astype(int)
    s = comparator_stats(np.bincount(chains, minlength=25))
    assert s.average_chain_length == pytest.approx(7.3, abs=0.05)
    assert 0.2 < s.async_to_sync_energy < 0.3
    assert s.async_delay_s < s.sync_delay_s  # 2.5 ns average against a 4.16 ns clock, as in the thesis


def test_pricing_validates_histogram() -> None:
    with pytest.raises(ValueError):
        comparator_stats(np.zeros(10, dtype=np.int64))
    with pytest.raises(ValueError):
        comparator_stats(-np.ones(25, dtype=np.int64))
    empty = comparator_stats(np.zeros(25, dtype=np.int64))
    assert empty.comparisons == 0 and empty.sync_energy_j == 0.0 and np.isnan(empty.average_chain_length)
