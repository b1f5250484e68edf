"""Settings packing: one value index per parameter, 4 bits each, in a 32-bit integer (parameter 0 in the
lowest bits), and the parameter descriptions a store carries to name the values (the one packing
implementation; ``service.params`` uses it)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

BITS_PER_PARAM = 4
MAX_VALUES_PER_PARAM = 1 << BITS_PER_PARAM
MAX_PARAMS = 32 // BITS_PER_PARAM


def pack_indices(indices: Sequence[int]) -> int:
    """Pack per-parameter value indices into one 32-bit integer, 4 bits each, parameter 0 lowest."""
    if len(indices) > MAX_PARAMS:
        raise ValueError(f"at most {MAX_PARAMS} parameters fit in 32 bits, got {len(indices)}")
    packed = 0
    for i, v in enumerate(indices):
        iv = int(v)
        if iv != v or not 0 <= iv < MAX_VALUES_PER_PARAM:
            raise ValueError(f"parameter {i} index {v!r} is outside 0..{MAX_VALUES_PER_PARAM - 1}")
        packed |= iv << (BITS_PER_PARAM * i)
    return packed


def unpack_indices(packed: int, n_params: int) -> tuple[int, ...]:
    """Inverse of :func:`pack_indices`; bits above the last parameter must be zero."""
    if not 0 <= n_params <= MAX_PARAMS:
        raise ValueError(f"n_params must be in 0..{MAX_PARAMS}, got {n_params}")
    p = int(packed)
    if p != packed or p < 0 or p >> (BITS_PER_PARAM * n_params):
        raise ValueError(f"packed value {packed!r} does not fit {n_params} parameters of 4 bits")
    mask = MAX_VALUES_PER_PARAM - 1
    return tuple((p >> (BITS_PER_PARAM * i)) & mask for i in range(n_params))


def pack_array(indices: np.ndarray) -> np.ndarray:
    """Vectorised :func:`pack_indices` for an (N, P) integer array; returns uint32 (N,)."""
    a = np.asarray(indices)
    if a.ndim != 2 or a.shape[1] > MAX_PARAMS:
        raise ValueError(f"expected (N, <= {MAX_PARAMS}) indices, got shape {a.shape}")
    if a.size and (a.min() < 0 or a.max() >= MAX_VALUES_PER_PARAM):
        raise ValueError("indices must be in 0..15")
    shifts = (BITS_PER_PARAM * np.arange(a.shape[1])).astype(np.uint32)
    out = np.zeros(a.shape[0], dtype=np.uint32)
    for j in range(a.shape[1]):
        out |= a[:, j].astype(np.uint32) << shifts[j]
    return out


def unpack_array(packed: np.ndarray, n_params: int) -> np.ndarray:
    """Vectorised :func:`unpack_indices`; returns int64 (N, n_params)."""
    p = np.asarray(packed, dtype=np.uint64).reshape(-1)
    shifts = (BITS_PER_PARAM * np.arange(n_params)).astype(np.uint64)
    return ((p[:, None] >> shifts) & np.uint64(MAX_VALUES_PER_PARAM - 1)).astype(np.int64)


@dataclass(frozen=True)
class StoredParameter:
    """Name, ordered values and the index of the maximum-quality value of one parameter (enough to
    name settings without ``service.params``)."""

    name: str
    values: tuple[Any, ...]
    max_quality: int

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "values": list(self.values), "max_quality": self.max_quality}

    @staticmethod
    def from_dict(d: dict[str, Any]) -> StoredParameter:
        values = tuple(_freeze(v) for v in d["values"])
        mq = int(d["max_quality"])
        if not values or not 0 <= mq < len(values):
            raise ValueError(f"parameter {d.get('name')!r}: bad values or max_quality")
        return StoredParameter(str(d["name"]), values, mq)


def _freeze(v: Any) -> Any:
    if isinstance(v, list):
        return tuple(_freeze(x) for x in v)
    if isinstance(v, dict):
        return tuple(sorted((k, _freeze(x)) for k, x in v.items()))
    return v


def thaw(v: Any) -> Any:
    """A stored value as JSON-friendly data (tuples back to lists)."""
    if isinstance(v, tuple):
        return [thaw(x) for x in v]
    return v


def settings_of(parameters: Sequence[StoredParameter], indices: Sequence[int]) -> dict[str, Any]:
    """Parameter name -> value for value indices (JSON-friendly values)."""
    return {p.name: thaw(p.values[i]) for p, i in zip(parameters, indices, strict=True)}
