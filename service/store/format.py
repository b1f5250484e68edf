"""The store's versioned JSON document: what each field holds, writing it and reading it back.

Layout (power-budget paper, sec. 4.2 and 6):

- an octree over the camera path: ``root_min``/``root_size`` give the cubic root; every node is either a
  leaf (``children[n] == -1``) or has eight consecutive children starting at ``children[n]``; child ``k``
  covers the upper half along x if ``k & 1``, along y if ``k & 2``, along z if ``k & 4``;
- corners on an integer lattice of ``2**lattice_depth`` cells per root side (``corners``), each with six
  view frontiers (``corner_views``, view order :data:`~service.store.camera.VIEW_NAMES`). A view is the
  cube face (cone of directions around its axis) a camera's frustum mostly falls into; its frontier was
  measured at a *sample direction*: the axis itself (version 1, or ``view_dirs`` absent) or, since
  version 2, a per-(corner, view) direction aimed at what the path's cameras looking through that face
  see (``view_dirs``: int8 codes). Since version 3 a store may instead give every *frontier* the camera
  it was measured at (``frontier_dirs``: int16 directions, ``frontier_eyes``: uint16 positions over the
  root cube): path-sampled stores measure each face at the path camera that best represents the frames
  looking it up, and faces that inherit that frontier share its camera;
- frontiers: lists of (packed settings, error, power), power ascending and error descending (per tier
  since version 5, see frame times), shared
  between corners and views that inherit them: ``frontier_sizes``, indices into the unique ``settings``
  table (``frontier_settings``), error and power as 16-bit steps (error over [0, 1], power over
  [0, ``power_scale``]);
- frame times (version 4, optional): ``frontier_frame_time``, each frontier point's modelled frame time
  at the path's resolution as 16-bit steps over [0, ``frame_time_scale``] s, rounded so every point stays
  on its side of the frame period 1 / ``fps`` (:func:`service.store.codec.frame_time_codes`); power is
  what the GPU draws at the frame rate it reaches (``fps`` when the point meets it, else 1 / frame
  time). In version 4, where any point of a frontier meets ``fps`` only such points are kept. Since
  version 5 such a frontier has two tiers (:mod:`service.store.frontier`): its meeting points, then the
  points that miss ``fps`` but are more accurate than the most accurate meeting one (each tier power
  ascending; error descends over the whole frontier); the frame times tell the tiers apart (no new
  field), and a version-4 frontier reads as one without a slow tier. Absent (versions 1-3): frame times
  unknown, power as priced then (P_static + E * fps even for frames that missed);
- per-camera figures (optional, version 5 readers that do not know them read the worst figures
  above): where a frontier was priced at several cameras (path samples and their guard frames,
  :mod:`service.store.priced`), ``priced_cameras`` gives each frontier's camera count (0: none kept),
  the sample camera being the frontier's own (``frontier_eyes``/``frontier_dirs``), ``priced_eyes`` /
  ``priced_dirs`` the others' (the same codes), ``priced_scale`` (float32) the distance unit of the
  camera dissimilarity, and ``priced_error`` / ``priced_power`` each point's figures at each camera
  (camera major within a frontier; the same 16-bit steps and ``power_scale`` as the frontier's);
  optionally (in version 5 and 6 documents; readers that do not know it draw the tiers from the worst
  frame times, as before) ``priced_frame_time``, each point's frame time at each camera on the
  frontiers' frame-time steps (``frame_time_scale``, each on its side of the frame period: the lookup
  draws each frame's tiers from their interpolation, :mod:`service.store.lookup`);
- ``parameters`` (names, values, maximum-quality index), ``profile``, ``fps``, ``vfov``, ``aspect``
  and the optimiser's ``meta``.

Arrays are little-endian base64 blobs (:mod:`service.store.codec`). Readers accept versions 1-6.

Version 6 holds the same codes in about two thirds of the bytes (bench/RESULTS.md, "The store's size
with per-camera figures"); every decoded figure is what version 5's document of the same store decodes
to, and ``to_dict(store, 5)`` still writes version 5 byte for byte as before, for readers of versions 1-5:

- small integers (``corner_views``, ``settings``, ``frontier_sizes``, ``frontier_settings``,
  ``priced_cameras``, ``corners``) are bit-packed at the fewest bits that hold the largest
  (:func:`service.store.codec.encode_bits`);
- ``node_splits`` (one bit per node: split or leaf) replaces ``children`` where every split node's
  children follow the previous split's, as the optimiser numbers them; ``corners`` is left out where
  the corners are in the order the optimiser's lattice creates them (:func:`lattice_corners`);
- per-camera figures: a frontier's stored figures are the worst over its cameras, so one camera of
  each point holds the frontier's own code. ``priced_error_worst`` gives, for every point of a
  frontier priced at several cameras, the first camera at the frontier's error code, and
  ``priced_error_below`` every other camera's code as its distance below it (camera major within a
  frontier); the same for power (``priced_power_worst``, ``priced_power_below``) and frame time
  (``priced_frame_time_worst``, ``priced_frame_time_below``). A frontier priced at one camera has its
  own codes there.

Each of these is written only where the store allows it (the per-camera split also only where it is
shorter: in a store of a few points its second field can cost more than it saves); otherwise the field
is written as version 5 wrote it (``children``, ``corners``, ``priced_error`` / ``priced_power`` /
``priced_frame_time``) and read as before.

Adding a field: write it in :func:`to_dict` (optional fields only when set, so older readers and
byte-identical stores are unaffected), read it in :func:`fields_from_dict` (absent -> the old
meaning), add the attribute to ``ParetoStore`` with its validation, bump :data:`FORMAT_VERSION` when
older readers would misread a store that has it, and extend ``tests/test_pareto_store.py``.
"""

from __future__ import annotations

import itertools
import json
from typing import Any

import numpy as np

from . import codec
from .camera import VIEW_NAMES
from .frontier import Frontier
from .packing import StoredParameter
from .priced import PricedFigures

FORMAT_NAME = "render-budget/pareto-store"
FORMAT_VERSION = 6
#: Versions this reader accepts (version 1 stores have axis-aligned sample views at the corners,
#: version 2 adds sample directions, version 3 sample eyes, version 4 frame times, version 5 the slow
#: tier of settings that miss the frame rate, version 6 the compact encodings: the same figures).
READABLE_VERSIONS = (1, 2, 3, 4, 5, 6)
#: Versions :func:`to_dict` writes (5: the layout before the compact encodings, for readers of 1-5).
WRITABLE_VERSIONS = (5, 6)
_SEPARATORS = (",", ":")  # documents are written without spaces


def to_dict(store: Any, version: int = FORMAT_VERSION) -> dict[str, Any]:
    """The versioned JSON document of a ``ParetoStore``: format :data:`FORMAT_VERSION`, or ``version`` 5
    (the layout before the compact encodings: what readers of versions 1-5 read, byte for byte what
    this module wrote then)."""
    if version not in WRITABLE_VERSIONS:
        raise ValueError(f"cannot write store version {version!r} (writer: {WRITABLE_VERSIONS})")
    compact = version >= 6
    frontiers = store.frontiers
    all_packed = np.concatenate([f.packed for f in frontiers]) if frontiers else np.zeros(0)
    table, inverse = np.unique(all_packed.astype(np.uint32), return_inverse=True)
    sizes = np.asarray([len(f) for f in frontiers], dtype=np.int64)
    err = np.concatenate([f.error for f in frontiers]) if frontiers else np.zeros(0)
    pw = np.concatenate([f.power_w for f in frontiers]) if frontiers else np.zeros(0)
    if err.size and (err.min() < 0 or err.max() > 1):
        raise ValueError("frontier errors must lie in [0, 1] to be stored")
    if pw.size and pw.min() < 0:
        raise ValueError("frontier power must be non-negative to be stored")
    power_scale = float(pw.max()) if pw.size and pw.max() > 0 else 1.0
    eq = np.rint(err * codec.QMAX).astype(np.int64)
    pq = np.rint(pw / power_scale * codec.QMAX).astype(np.int64)
    side = 1 << store.lattice_depth
    extra = {}
    if store.view_dirs is not None:
        extra["view_dirs"] = codec.encode(codec.direction_codes(store.view_dirs).reshape(-1), "<i1")
    if store.frontier_dirs is not None and store.frontier_eyes is not None:
        extra["frontier_dirs"] = codec.encode(
            codec.direction_codes(store.frontier_dirs, codec.DIR_Q16).reshape(-1), "<i2")
        extra["frontier_eyes"] = codec.encode(
            codec.eye_codes(store.frontier_eyes, store.root_min, store.root_size).reshape(-1), "<u2")
    tq: tuple[np.ndarray, float] | None = None
    if store.frame_times_known:
        tq = codec.frame_time_codes(np.concatenate([f.frame_time_s for f in frontiers]), store.fps)
    if store.priced is not None:
        extra.update(_priced_fields(store, power_scale, eq, pq, tq, compact))
    if tq is not None:
        extra["frontier_frame_time"] = codec.encode(tq[0], "<u2")
        extra["frame_time_scale"] = tq[1]
    ints = codec.encode_bits if compact else None  # small integers: bit-packed since version 6
    return {
        "format": FORMAT_NAME,
        "version": version,
        "profile": store.profile,
        "fps": store.fps,
        "vfov": store.vfov,
        "aspect": store.aspect,
        "views": list(VIEW_NAMES),
        "parameters": [p.to_dict() for p in store.parameters],
        "root_min": [float(c) for c in store.root_min],
        "root_size": store.root_size,
        "lattice_depth": store.lattice_depth,
        **(_tree_fields(store) if compact else {
            "children": codec.encode(store.children, "<i4"),
            "corners": codec.encode(store.corner_coords, codec.uint_dtype(side))}),
        "corner_views": ints(store.corner_views) if ints else codec.encode(
            store.corner_views, codec.uint_dtype(max(len(frontiers), 1))),
        "settings": ints(table) if ints else codec.encode(table, "<u4"),
        "frontier_sizes": ints(sizes) if ints else codec.encode(
            sizes, codec.uint_dtype(int(sizes.max()) if sizes.size else 0)),
        "frontier_settings": ints(inverse) if ints else codec.encode(
            inverse, codec.uint_dtype(max(table.size, 1))),
        "frontier_error": codec.encode(eq, "<u2"),
        "frontier_power": codec.encode(pq, "<u2"),
        "power_scale": power_scale,
        "meta": store.meta,
        **extra,
    }


Point = tuple[int, int, int]


def box_corners(origin: Point, size: int) -> list[Point]:
    """The eight corners of the lattice box at ``origin`` with side ``size``, in the store's child order
    (x if ``k & 1``, y if ``k & 2``, z if ``k & 4``); with half the side, the origins of its children."""
    x, y, z = origin
    return [(x + size * (k & 1), y + size * ((k >> 1) & 1), z + size * ((k >> 2) & 1)) for k in range(8)]


def split_points(origin: Point, size: int) -> list[Point]:
    """The 27 lattice points of a box split in two along each axis (x slowest, z fastest): the order in
    which a split creates its new corners."""
    x, y, z = origin
    h = size // 2
    return [(x + h * i, y + h * j, z + h * k) for i, j, k in itertools.product(range(3), repeat=3)]


def lattice_corners(children: np.ndarray, lattice_depth: int) -> np.ndarray:
    """The corners of an octree in the order the optimiser's lattice creates them
    (:class:`service.octree.lattice.Lattice`): the root's eight (child order: x if ``k & 1``, y if
    ``k & 2``, z if ``k & 4``), then, for each split node in the order of its first child, the new ones
    among its 27 lattice points (x slowest, z fastest). (C, 3) int64 lattice coordinates; ValueError
    if the tree is deeper than its lattice or a node is split before it exists."""
    side = 1 << int(lattice_depth)
    ch = np.asarray(children, dtype=np.int64).reshape(-1)
    boxes: dict[int, tuple[Point, int]] = {0: ((0, 0, 0), side)}
    index: dict[Point, int] = {}
    for xyz in box_corners((0, 0, 0), side):
        index.setdefault(xyz, len(index))
    split = np.flatnonzero(ch >= 0)
    for n in split[np.argsort(ch[split], kind="stable")].tolist():
        box = boxes.get(n)
        if box is None:
            raise ValueError("a node is split before it is created")
        origin, size = box
        if size < 2 or size % 2:
            raise ValueError("the octree is deeper than its lattice")
        first = int(ch[n])
        for k, child in enumerate(box_corners(origin, size // 2)):
            boxes[first + k] = (child, size // 2)
        for xyz in split_points(origin, size):
            index.setdefault(xyz, len(index))
    return np.asarray(list(index), dtype=np.int64).reshape(-1, 3)


def _tree_fields(store: Any) -> dict[str, Any]:
    """The octree and its corners (version 6): ``node_splits`` when every split node's children follow
    the previous split's (the lattice's creation order), else ``children``; ``corners`` only when they
    are not the lattice's order (:func:`lattice_corners`)."""
    ch = np.asarray(store.children, dtype=np.int64)
    split = np.flatnonzero(ch >= 0)
    out: dict[str, Any] = {}
    first = 1 + 8 * np.arange(split.size)
    if np.array_equal(ch[split], first) and ch.size == 1 + 8 * split.size and np.all(split < first):
        out["node_splits"] = codec.encode_bits(ch >= 0, 1)
    else:
        out["children"] = codec.encode(ch, "<i4")
    try:
        derived = lattice_corners(ch, store.lattice_depth)
    except ValueError:
        derived = None
    if derived is None or not np.array_equal(derived, store.corner_coords):
        out["corners"] = codec.encode_bits(store.corner_coords)
    return out


def _children(d: dict[str, Any]) -> np.ndarray:
    """The octree's first-child array: ``children`` or (version 6) ``node_splits``."""
    if "node_splits" not in d:
        return codec.decode(d["children"])
    if "children" in d:
        raise ValueError("a store gives its octree once: children or node_splits")
    split = codec.decode(d["node_splits"])
    nodes = np.flatnonzero(split)
    first = 1 + 8 * np.arange(nodes.size, dtype=np.int64)
    if split.max(initial=0) > 1 or split.size != 1 + 8 * nodes.size or np.any(nodes >= first):
        raise ValueError("node_splits is not an octree in creation order")
    ch = np.full(split.size, -1, dtype=np.int64)
    ch[nodes] = first
    return ch


def _priced_fields(store: Any, power_scale: float, eq: np.ndarray, pq: np.ndarray,
                   tq: tuple[np.ndarray, float] | None, compact: bool) -> dict[str, Any]:
    """The per-camera figures' fields (:mod:`service.store.priced`); ``eq`` / ``pq`` / ``tq`` (frame
    time codes and their scale, None: no frame times): the frontiers' 16-bit codes (each point's worst
    figures), which ``compact`` (version 6) encodes them against."""
    if store.frontier_eyes is None or store.frontier_dirs is None:
        raise ValueError("per-camera figures need the frontiers' sample cameras (frontier_eyes and dirs)")
    counts, scales, eyes, dirs, err, pw, ft = [], [], [], [], [], [], []
    for pf in store.priced:
        counts.append(0 if pf is None else pf.cameras)
        if pf is None:
            continue
        scales.append(pf.scale)
        eyes.append(pf.eyes[1:])
        dirs.append(pf.forwards[1:])
        err.append(pf.error.reshape(-1))
        pw.append(pf.power_w.reshape(-1))
        if pf.frame_time_s is not None:
            ft.append(pf.frame_time_s.reshape(-1))
    e, p = np.concatenate(err), np.concatenate(pw)
    if e.size and (e.min() < 0 or e.max() > 1):
        raise ValueError("per-camera errors must lie in [0, 1] to be stored")
    if p.size and (p.min() < 0 or p.max() > power_scale * (1 + 1e-9)):
        raise ValueError("per-camera power must lie in [0, the frontiers' largest power] to be stored")
    eyes_a, dirs_a = np.concatenate(eyes).reshape(-1, 3), np.concatenate(dirs).reshape(-1, 3)
    e_codes = np.rint(e * codec.QMAX).astype(np.int64)
    p_codes = np.minimum(np.rint(p / power_scale * codec.QMAX), codec.QMAX).astype(np.int64)
    out = {
        "priced_cameras": codec.encode_bits(counts) if compact else codec.encode(np.asarray(counts), "<u1"),
        "priced_scale": codec.encode(np.asarray(scales), "<f4"),
        "priced_eyes": codec.encode(codec.eye_codes(eyes_a, store.root_min, store.root_size).reshape(-1),
                                    "<u2"),
        "priced_dirs": codec.encode(codec.direction_codes(dirs_a, codec.DIR_Q16).reshape(-1), "<i2"),
    }
    sizes = [len(f) for f in store.frontiers]
    figures = [("error", e_codes, eq), ("power", p_codes, pq)]
    if ft:  # (every priced frontier's or none: ParetoStore checks it) on the frontiers' frame-time steps
        if tq is None:
            raise ValueError("per-camera frame times need the frontiers' frame times")
        figures.append(("frame_time", codec.frame_time_codes(np.concatenate(ft), store.fps, tq[1])[0]
                        .astype(np.int64), tq[0].astype(np.int64)))
    for name, codes, worst in figures:
        fields = {f"priced_{name}": codec.encode(codes, "<u2")}
        split = _below_worst(codes, worst, counts, sizes) if compact else None
        if split is not None:
            at_worst, below = split
            pair = {f"priced_{name}_worst": codec.encode_bits(at_worst),
                    f"priced_{name}_below": codec.encode_bits(below)}
            if _json_size(pair) < _json_size(fields):  # (at a few points the second field costs more)
                fields = pair
        out.update(fields)
    return out


def _json_size(fields: dict[str, Any]) -> int:
    """The bytes ``fields`` take in a document as :func:`to_json` writes it."""
    return len(json.dumps(fields, separators=_SEPARATORS))


def _below_worst(codes: np.ndarray, worst: np.ndarray, counts: list[int], sizes: list[int]
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """Per-camera codes (each priced frontier's K x n, camera major) as what they add to the
    frontier's own codes ``worst`` (the worst over its cameras, one camera holding it): for every point
    of a frontier priced at several cameras the first camera at the worst code, and every other
    camera's code as its distance below the worst (camera major). None when some point's worst code is
    not its cameras' largest (then the codes are stored as they are)."""
    at, below = [], []
    v = w = 0
    for k, n in zip(counts, sizes, strict=True):
        if k == 0:
            w += n
            continue
        c = codes[v:v + k * n].reshape(k, n)
        top = worst[w:w + n]
        if not np.array_equal(c.max(axis=0), top):
            return None
        if k > 1:
            first = c.argmax(axis=0)
            others = np.ones((k, n), dtype=bool)
            others[first, np.arange(n)] = False
            at.append(first)
            below.append((top[None, :] - c)[others])
        v, w = v + k * n, w + n
    empty = np.zeros(0, dtype=np.int64)
    return (np.concatenate(at) if at else empty), (np.concatenate(below) if below else empty)


def _priced_codes(d: dict[str, Any], name: str, counts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """The per-camera 16-bit codes of ``name`` (error, power or frame_time), camera major per frontier, from
    ``priced_<name>`` or (version 6) from the frontiers' codes with ``priced_<name>_worst`` / ``_below``."""
    if f"priced_{name}" in d:
        return codec.decode(d[f"priced_{name}"]).astype(np.int64)
    worst = codec.decode(d[f"frontier_{name}"]).astype(np.int64)
    at = codec.decode(d[f"priced_{name}_worst"])
    below = codec.decode(d[f"priced_{name}_below"])
    multi = counts > 1
    if (worst.size != int(sizes.sum()) or at.size != int(sizes[multi].sum())
            or below.size != int(((counts[multi] - 1) * sizes[multi]).sum())):
        raise ValueError(f"per-camera {name} figures disagree in length with their cameras and frontiers")
    out = []
    a = b = w = 0
    for k, n in zip(counts.tolist(), sizes.tolist(), strict=True):
        top = worst[w:w + n]
        w += n
        if k == 0:
            continue
        c = np.repeat(top[None, :], k, axis=0)
        if k > 1:
            first = at[a:a + n]
            if first.max(initial=0) >= k:
                raise ValueError(f"per-camera {name} figures name a missing camera")
            others = np.ones((k, n), dtype=bool)
            others[first, np.arange(n)] = False
            c[others] -= below[b:b + (k - 1) * n]
            a, b = a + n, b + (k - 1) * n
        out.append(c.reshape(-1))
    codes = np.concatenate(out) if out else np.zeros(0, dtype=np.int64)
    if codes.size and codes.min() < 0:
        raise ValueError(f"per-camera {name} figures below zero")
    return codes


def to_json(store: Any, version: int = FORMAT_VERSION) -> str:
    return json.dumps(to_dict(store, version), separators=_SEPARATORS, allow_nan=False)


def _frontiers(d: dict[str, Any]) -> list[Frontier]:
    sizes = codec.decode(d["frontier_sizes"]).astype(np.int64)
    table = codec.decode(d["settings"]).astype(np.uint32)
    idx = codec.decode(d["frontier_settings"]).astype(np.int64)
    eq = codec.decode(d["frontier_error"]).astype(np.float64) / codec.QMAX
    pq = codec.decode(d["frontier_power"]).astype(np.float64) / codec.QMAX * float(d["power_scale"])
    tq = None
    if d.get("version", 1) >= 4 and d.get("frontier_frame_time") is not None:
        scale = float(d["frame_time_scale"])
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError("frame_time_scale must be positive and finite")
        tq = codec.frame_times(codec.decode(d["frontier_frame_time"]), scale)
        if tq.size != idx.size:
            raise ValueError("frontier frame times disagree in length with the frontiers")
    if not (idx.size == eq.size == pq.size == int(sizes.sum())):
        raise ValueError("frontier arrays disagree in length")
    if idx.size and idx.max() >= table.size:
        raise ValueError("frontier refers to a missing settings entry")
    frontiers = []
    off = 0
    for n in sizes:
        sl = slice(off, off + int(n))
        frontiers.append(Frontier(table[idx[sl]], eq[sl], pq[sl], None if tq is None else tq[sl]))
        off += int(n)
    return frontiers


def _sample_cameras(d: dict[str, Any]) -> dict[str, Any]:
    """The optional sample directions (version 2) and sample eyes (version 3)."""
    out: dict[str, Any] = {"view_dirs": None, "frontier_dirs": None, "frontier_eyes": None}
    if d.get("version", 1) >= 2 and d.get("view_dirs") is not None:
        vq = codec.decode(d["view_dirs"]).astype(np.float64)
        if vq.size % 18:
            raise ValueError("view_dirs length is not a multiple of 6 x 3")
        out["view_dirs"] = vq.reshape(-1, 6, 3)
    if d.get("version", 1) >= 3 and d.get("frontier_dirs") is not None:
        out["frontier_dirs"] = codec.decode(d["frontier_dirs"]).astype(np.float64).reshape(-1, 3)
        out["frontier_eyes"] = codec.decode_eyes(d["frontier_eyes"], d["root_min"], d["root_size"])
    return out


def _priced(d: dict[str, Any], frontiers: list[Frontier], cams: dict[str, Any]) -> list[Any] | None:
    """The per-camera figures (None: the store keeps none)."""
    if d.get("priced_cameras") is None:
        return None
    counts = codec.decode(d["priced_cameras"]).astype(np.int64)
    if counts.size != len(frontiers):
        raise ValueError("priced_cameras disagrees in length with the frontiers")
    if cams["frontier_eyes"] is None:
        raise ValueError("per-camera figures need the frontiers' sample cameras")
    scales = codec.decode(d["priced_scale"]).astype(np.float64)
    eyes = codec.decode_eyes(d["priced_eyes"], d["root_min"], d["root_size"])
    dirs = codec.decode(d["priced_dirs"]).astype(np.float64).reshape(-1, 3)
    sizes = np.asarray([len(f) for f in frontiers], dtype=np.int64)
    err = _priced_codes(d, "error", counts, sizes).astype(np.float64) / codec.QMAX
    pw = _priced_codes(d, "power", counts, sizes).astype(np.float64) / codec.QMAX * float(d["power_scale"])
    ft = None
    if "priced_frame_time" in d or "priced_frame_time_worst" in d:
        if d.get("frontier_frame_time") is None:
            raise ValueError("per-camera frame times need the frontiers' frame times")
        ft = codec.frame_times(_priced_codes(d, "frame_time", counts, sizes), float(d["frame_time_scale"]))
    priced = counts > 0
    guards = int((counts[priced] - 1).sum())
    values = int(sum(int(k) * len(f) for k, f in zip(counts, frontiers, strict=True)))
    if (scales.size != int(priced.sum()) or eyes.shape[0] != guards or dirs.shape[0] != guards
            or err.size != values or pw.size != values or (ft is not None and ft.size != values)):
        raise ValueError("per-camera figures disagree in length with their cameras and frontiers")
    out: list[Any] = []
    g = v = s = 0
    for f, (k, fr) in enumerate(zip(counts.tolist(), frontiers, strict=True)):
        if k == 0:
            out.append(None)
            continue
        n = k * len(fr)
        out.append(PricedFigures(np.vstack([cams["frontier_eyes"][f], eyes[g:g + k - 1]]),
                                 np.vstack([cams["frontier_dirs"][f], dirs[g:g + k - 1]]), scales[s],
                                 fr.packed, err[v:v + n], pw[v:v + n], None if ft is None else ft[v:v + n]))
        g, v, s = g + k - 1, v + n, s + 1
    return out


def fields_from_dict(d: dict[str, Any]) -> dict[str, Any]:
    """``ParetoStore`` constructor arguments from a document (ValueError naming what is wrong)."""
    if not isinstance(d, dict) or d.get("format") != FORMAT_NAME:
        raise ValueError("not a render-budget Pareto store")
    if d.get("version") not in READABLE_VERSIONS:
        raise ValueError(f"unsupported store version {d.get('version')!r} (reader: {READABLE_VERSIONS})")
    try:
        frontiers = _frontiers(d)
        cams = _sample_cameras(d)
        children = _children(d)
        return {
            "parameters": tuple(StoredParameter.from_dict(p) for p in d["parameters"]),
            "root_min": np.asarray(d["root_min"], dtype=np.float64),
            "root_size": float(d["root_size"]),
            "lattice_depth": int(d["lattice_depth"]),
            "children": children,
            "corner_coords": (codec.decode(d["corners"]) if "corners" in d
                              else lattice_corners(children, int(d["lattice_depth"]))),
            "corner_views": codec.decode(d["corner_views"]),
            "frontiers": frontiers,
            "vfov": float(d["vfov"]),
            "aspect": float(d["aspect"]),
            "profile": str(d["profile"]),
            "fps": float(d["fps"]),
            "meta": dict(d.get("meta") or {}),
            **cams,
            "priced": _priced(d, frontiers, cams),
        }
    except (KeyError, TypeError) as exc:
        raise ValueError(f"malformed store: missing or wrong field {exc}") from exc


def fields_from_json(text: str | bytes) -> dict[str, Any]:
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"store is not valid JSON: {exc}") from exc
    return fields_from_dict(d)
