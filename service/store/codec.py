"""How a store keeps numbers: arrays as little-endian base64 blobs (``"<dtype>:<base64>"``, or, since
store format 6, non-negative integers at the fewest bits that hold them: ``"b<width>:<count>:<base64>"``,
:func:`encode_bits`), error, power and frame time as 16-bit steps, sample directions as cube-map style
integer codes, sample eyes as 16-bit steps over the root cube. The optimiser renders with the quantised
cameras, so a loaded store reports exactly the camera each frontier was measured at."""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

QMAX = 65535  # 16-bit error (over [0, 1]), power (over [0, power_scale]) and frame time steps
DIR_Q = 127  # int8 per-view sample directions (version 2)
DIR_Q16 = 32767  # int16 per-frontier sample directions (version 3, path cameras)
EYE_Q = 65535  # uint16 sample eyes over the root cube
_DTYPES = ("<i1", "<u1", "<i2", "<u2", "<u4", "<i4", "<f4", "<f8")


def encode(arr: Any, dtype: str) -> str:
    a = np.ascontiguousarray(np.asarray(arr).astype(dtype, copy=False))
    return f"{dtype}:" + base64.b64encode(a.tobytes()).decode("ascii")


def decode(text: str) -> np.ndarray:
    """The array of a blob written by :func:`encode` or :func:`encode_bits`."""
    dtype, _, data = str(text).partition(":")
    if dtype[:1] == "b":
        return _decode_bits(dtype, data)
    if dtype not in _DTYPES:
        raise ValueError(f"unsupported array dtype {dtype!r} in store")
    try:
        raw = base64.b64decode(data.encode("ascii"), validate=True)
    except ValueError as exc:
        raise ValueError(f"corrupt base64 array in store: {exc}") from exc
    if len(raw) % np.dtype(dtype).itemsize:
        raise ValueError("corrupt array length in store")
    return np.frombuffer(raw, dtype=dtype)


MAX_BITS = 32  # the widest bit-packed integers (packed settings are 32 bits)


def encode_bits(values: Any, width: int | None = None) -> str:
    """Non-negative integers (< 2**32) packed at ``width`` bits each (default: the fewest that hold the
    largest, at least 1), least significant bit first, the bits of consecutive values consecutive
    (little-endian bit order, zero padding to a whole byte): ``"b<width>:<count>:<base64>"``. Exact:
    :func:`decode` gives the values back as int64."""
    v = np.asarray(values)
    if v.size and not np.issubdtype(v.dtype, np.integer):
        if not np.array_equal(v, np.rint(v)):
            raise ValueError("only integers can be bit-packed")
    v = v.astype(np.int64).reshape(-1)
    top = int(v.max()) if v.size else 0
    w = max(1, top.bit_length()) if width is None else int(width)
    if v.size and v.min() < 0:
        raise ValueError("only non-negative integers can be bit-packed")
    if not 1 <= w <= MAX_BITS or top >= 1 << w:
        raise ValueError(f"bit width {w} cannot hold {top} (1..{MAX_BITS} bits)")
    bits = ((v[:, None] >> np.arange(w, dtype=np.int64)) & 1).astype(np.uint8).reshape(-1)
    raw = np.packbits(bits, bitorder="little")
    return f"b{w}:{v.size}:" + base64.b64encode(raw.tobytes()).decode("ascii")


def _decode_bits(dtype: str, data: str) -> np.ndarray:
    width, (count_text, _, payload) = dtype[1:], data.partition(":")
    if not (width.isdigit() and count_text.isdigit() and 1 <= int(width) <= MAX_BITS):
        raise ValueError(f"unsupported bit-packed array {dtype!r} in store")
    w, count = int(width), int(count_text)
    try:
        raw = base64.b64decode(payload.encode("ascii"), validate=True)
    except ValueError as exc:
        raise ValueError(f"corrupt base64 array in store: {exc}") from exc
    if len(raw) != (count * w + 7) // 8:
        raise ValueError("corrupt bit-packed array length in store")
    bits = np.unpackbits(np.frombuffer(raw, dtype=np.uint8), bitorder="little")
    if bits[count * w:].any():
        raise ValueError("corrupt bit-packed array padding in store")
    return bits[:count * w].reshape(count, w).astype(np.int64) @ (np.int64(1) << np.arange(w, dtype=np.int64))


def uint_dtype(max_value: int) -> str:
    """The smallest unsigned dtype holding ``max_value``."""
    return "<u1" if max_value < 256 else "<u2" if max_value < 65536 else "<u4"


def direction_codes(d: np.ndarray, q: int = DIR_Q) -> np.ndarray:
    """Integer codes of directions: scaled so the largest component is +-q (a cube-map style code, so
    decoding and re-encoding gives the same codes); int8 for q = 127, int16 for q = 32767."""
    m = np.abs(d).max(axis=-1, keepdims=True)
    if np.any(m < 1e-300):
        raise ValueError("directions must be non-zero")
    return np.rint(d / m * q).astype(np.int8 if q <= 127 else np.int16)


def quantise_directions(directions: Any, *, fine: bool = False) -> np.ndarray:
    """Unit vectors (..., 3) rounded to the grid the store keeps (int8 per-view directions, or int16
    per-frontier ones when ``fine``: a path camera's direction to ~0.002 degrees), renormalised."""
    d = np.asarray(directions, dtype=np.float64)
    if d.shape[-1:] != (3,) or not np.all(np.isfinite(d)):
        raise ValueError("directions must be finite (..., 3) vectors")
    q = direction_codes(d, DIR_Q16 if fine else DIR_Q).astype(np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def eye_codes(eyes: Any, root_min: Any, root_size: float) -> np.ndarray:
    u = (np.asarray(eyes, dtype=np.float64) - np.asarray(root_min, dtype=np.float64)) / float(root_size)
    return np.rint(np.clip(u, 0.0, 1.0) * EYE_Q).astype(np.uint16)


def quantise_eyes(eyes: Any, root_min: Any, root_size: float) -> np.ndarray:
    """Sample eyes as the store keeps them: uint16 steps over the root cube (clamped into it)."""
    rm = np.asarray(root_min, dtype=np.float64)
    return rm + eye_codes(eyes, rm, root_size).astype(np.float64) / EYE_Q * float(root_size)


def decode_eyes(text: str, root_min: Any, root_size: float) -> np.ndarray:
    """Inverse of the eye codes: (F, 3) world positions."""
    return (np.asarray(root_min, dtype=np.float64)
            + decode(text).astype(np.float64).reshape(-1, 3) / EYE_Q * float(root_size))


def frame_times(codes: np.ndarray, scale: float) -> np.ndarray:
    """Frame times (s) of their 16-bit codes over [0, ``scale``] (the one decoding; writer and reader)."""
    return np.asarray(codes).astype(np.float64) / QMAX * float(scale)


def frame_time_codes(times: Any, fps: float, scale: float | None = None) -> tuple[np.ndarray, float]:
    """16-bit codes of frame times over [0, scale] (``scale``, by default the largest time) and the
    scale, rounded up except where that would carry a frame time past the frame period 1 / ``fps``:
    every setting decodes on its own side of the period (one that meets the store's frame rate still
    meets it after a round trip, one that misses it still misses it, never by less than it did). The
    codes are non-decreasing in the time (the largest time gets the largest code)."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if not (np.all(np.isfinite(t)) and np.all(t >= 0)):
        raise ValueError("frame times must be finite and >= 0 to be stored")
    if scale is None:
        scale = float(t.max()) if t.size and t.max() > 0 else 1.0
    elif t.size and t.max() > scale:
        raise ValueError("frame times above their scale cannot be stored")
    period = 1.0 / fps  # meets_frame_rate's test, vectorised
    q = np.clip(np.rint(t / scale * QMAX), 0, QMAX).astype(np.int64)
    q = np.minimum(q + (frame_times(q, scale) < t), QMAX)  # the smallest code at or above t (stable)
    meets = t <= period
    crossed = meets & ~(frame_times(q, scale) <= period)
    if crossed.any():  # the largest code still within the period
        k = int(np.floor(period / scale * QMAX))
        while k > 0 and not frame_times(np.asarray(k), scale) <= period:
            k -= 1
        q[crossed] = k
    while True:  # a missing frame rounded onto the period (a float edge): one step up
        crossed = ~meets & (frame_times(q, scale) <= period)
        if not crossed.any():
            break
        q[crossed] = np.minimum(q[crossed] + 1, QMAX)
    return q.astype(np.uint16), scale
