"""The closest-hit comparator's energy and delay (the thesis's Table 4.1): a render's histogram of
compute-chain lengths priced with the synchronous and the asynchronous comparator."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _core

# Thesis Table 4.1 (24-bit comparator, 0.18 um TSMC, 1.8 V): compute chain (bits examined after the MSB)
# -> (sync delay ns, sync energy pJ, async delay ns, async energy pJ). Rows between are interpolated
# linearly; the measured points are exactly these.
COMPARATOR_TABLE: tuple[tuple[int, float, float, float, float], ...] = (
    (0, 0.59, 17.36, 0.55, 1.40),
    (4, 1.23, 18.16, 1.69, 3.23),
    (8, 1.85, 18.95, 2.87, 5.36),
    (12, 2.46, 19.74, 4.04, 7.39),
    (16, 3.08, 20.53, 5.20, 9.37),
    (20, 3.69, 21.32, 6.37, 11.40),
    (23, 4.16, 22.00, 7.24, 12.89),
)


@dataclass(frozen=True)
class ComparatorStats:
    """Closest-hit comparisons priced with the synchronous and the asynchronous comparator (Table 4.1)."""

    histogram: np.ndarray  # comparisons per compute-chain length 0..24 (24: equal over all 24 bits)
    comparisons: int
    average_chain_length: float
    sync_energy_j: float
    async_energy_j: float
    async_to_sync_energy: float  # 0 comparisons -> nan
    sync_delay_s: float  # total comparator latency if run back to back
    async_delay_s: float


def _table_columns() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.asarray(COMPARATOR_TABLE, dtype=np.float64)
    return t[:, 0], t[:, 1], t[:, 2], t[:, 3], t[:, 4]


def chain_energies(energy_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(synchronous, asynchronous) energy (J) of one comparison by compute-chain length 0..24: a
    histogram's energy is its dot product with these (Table 4.1, scaled by ``energy_scale``)."""
    bits = int(_core.COMPARATOR_BITS)
    # Table 4.1 stops at 23 bits after the MSB (all 24 examined); "equal over all bits" costs the same.
    chain = np.minimum(np.arange(bits + 1, dtype=np.float64), 23.0)
    k, _sd, se, _ad, ae = _table_columns()
    return np.interp(chain, k, se) * 1e-12 * energy_scale, np.interp(chain, k, ae) * 1e-12 * energy_scale


def comparator_stats(histogram: np.ndarray | None, energy_scale: float = 1.0) -> ComparatorStats:
    """Price a chain-length histogram with Table 4.1 (J, scaled by ``energy_scale`` for the process)."""
    bits = int(_core.COMPARATOR_BITS)
    if histogram is None:
        h = np.zeros(bits + 1, dtype=np.int64)
    else:
        h = np.asarray(histogram)
        if h.ndim != 1 or h.shape[0] != bits + 1:
            raise ValueError(f"comparator histogram must have {bits + 1} entries, got shape {h.shape}")
        if not np.issubdtype(h.dtype, np.integer) or (h < 0).any():
            raise ValueError("comparator histogram must hold non-negative integer counts")
        h = h.astype(np.int64)
    n = int(h.sum())
    lengths = np.arange(bits + 1, dtype=np.float64)
    sync_e, async_e = chain_energies(energy_scale)
    k, sd, _se, ad, _ae = _table_columns()
    async_d = np.interp(np.minimum(lengths, 23.0), k, ad) * 1e-9
    # The synchronous comparator's delay is its worst case whatever the operands (clock period, Table 4.1).
    sync_total_e = float(h @ sync_e)
    async_total_e = float(h @ async_e)
    return ComparatorStats(
        histogram=h,
        comparisons=n,
        average_chain_length=float(h @ lengths) / n if n else float("nan"),
        sync_energy_j=sync_total_e,
        async_energy_j=async_total_e,
        async_to_sync_energy=async_total_e / sync_total_e if n else float("nan"),
        sync_delay_s=n * float(sd[-1]) * 1e-9,
        async_delay_s=float(h @ async_d),
    )
