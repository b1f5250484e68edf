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
- ``parameters`` (names, values, maximum-quality index), ``profile``, ``fps``, ``vfov``, ``aspect``
  and the optimiser's ``meta``.

Arrays are little-endian base64 blobs (:mod:`service.store.codec`). Readers accept versions 1-5.

Adding a field: write it in :func:`to_dict` (optional fields only when set, so older readers and
byte-identical stores are unaffected), read it in :func:`fields_from_dict` (absent -> the old
meaning), add the attribute to ``ParetoStore`` with its validation, bump :data:`FORMAT_VERSION` when
older readers would misread a store that has it, and extend ``tests/test_pareto_store.py``.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from . import codec
from .camera import VIEW_NAMES
from .frontier import Frontier
from .packing import StoredParameter
from .priced import PricedFigures

FORMAT_NAME = "render-budget/pareto-store"
FORMAT_VERSION = 5
#: Versions this reader accepts (version 1 stores have axis-aligned sample views at the corners,
#: version 2 adds sample directions, version 3 sample eyes, version 4 frame times, version 5 the slow
#: tier of settings that miss the frame rate).
READABLE_VERSIONS = (1, 2, 3, 4, 5)


def to_dict(store: Any) -> dict[str, Any]:
    """The versioned JSON document of a ``ParetoStore``."""
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
    if store.priced is not None:
        extra.update(_priced_fields(store, power_scale))
    if store.frame_times_known:
        codes, scale = codec.frame_time_codes(np.concatenate([f.frame_time_s for f in frontiers]), store.fps)
        extra["frontier_frame_time"] = codec.encode(codes, "<u2")
        extra["frame_time_scale"] = scale
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "profile": store.profile,
        "fps": store.fps,
        "vfov": store.vfov,
        "aspect": store.aspect,
        "views": list(VIEW_NAMES),
        "parameters": [p.to_dict() for p in store.parameters],
        "root_min": [float(c) for c in store.root_min],
        "root_size": store.root_size,
        "lattice_depth": store.lattice_depth,
        "children": codec.encode(store.children, "<i4"),
        "corners": codec.encode(store.corner_coords, codec.uint_dtype(side)),
        "corner_views": codec.encode(store.corner_views, codec.uint_dtype(max(len(frontiers), 1))),
        "settings": codec.encode(table, "<u4"),
        "frontier_sizes": codec.encode(sizes, codec.uint_dtype(int(sizes.max()) if sizes.size else 0)),
        "frontier_settings": codec.encode(inverse, codec.uint_dtype(max(table.size, 1))),
        "frontier_error": codec.encode(eq, "<u2"),
        "frontier_power": codec.encode(pq, "<u2"),
        "power_scale": power_scale,
        "meta": store.meta,
        **extra,
    }


def _priced_fields(store: Any, power_scale: float) -> dict[str, Any]:
    """The per-camera figures' fields (:mod:`service.store.priced`)."""
    if store.frontier_eyes is None or store.frontier_dirs is None:
        raise ValueError("per-camera figures need the frontiers' sample cameras (frontier_eyes and dirs)")
    counts, scales, eyes, dirs, err, pw = [], [], [], [], [], []
    for pf in store.priced:
        counts.append(0 if pf is None else pf.cameras)
        if pf is None:
            continue
        scales.append(pf.scale)
        eyes.append(pf.eyes[1:])
        dirs.append(pf.forwards[1:])
        err.append(pf.error.reshape(-1))
        pw.append(pf.power_w.reshape(-1))
    e, p = np.concatenate(err), np.concatenate(pw)
    if e.size and (e.min() < 0 or e.max() > 1):
        raise ValueError("per-camera errors must lie in [0, 1] to be stored")
    if p.size and (p.min() < 0 or p.max() > power_scale * (1 + 1e-9)):
        raise ValueError("per-camera power must lie in [0, the frontiers' largest power] to be stored")
    eyes_a, dirs_a = np.concatenate(eyes).reshape(-1, 3), np.concatenate(dirs).reshape(-1, 3)
    return {
        "priced_cameras": codec.encode(np.asarray(counts), "<u1"),
        "priced_scale": codec.encode(np.asarray(scales), "<f4"),
        "priced_eyes": codec.encode(codec.eye_codes(eyes_a, store.root_min, store.root_size).reshape(-1),
                                    "<u2"),
        "priced_dirs": codec.encode(codec.direction_codes(dirs_a, codec.DIR_Q16).reshape(-1), "<i2"),
        "priced_error": codec.encode(np.rint(e * codec.QMAX), "<u2"),
        "priced_power": codec.encode(np.minimum(np.rint(p / power_scale * codec.QMAX), codec.QMAX), "<u2"),
    }


def to_json(store: Any) -> str:
    return json.dumps(to_dict(store), separators=(",", ":"), allow_nan=False)


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
    err = codec.decode(d["priced_error"]).astype(np.float64) / codec.QMAX
    pw = codec.decode(d["priced_power"]).astype(np.float64) / codec.QMAX * float(d["power_scale"])
    priced = counts > 0
    guards = int((counts[priced] - 1).sum())
    values = int(sum(int(k) * len(f) for k, f in zip(counts, frontiers, strict=True)))
    if (scales.size != int(priced.sum()) or eyes.shape[0] != guards or dirs.shape[0] != guards
            or err.size != values or pw.size != values):
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
                                 fr.packed, err[v:v + n], pw[v:v + n]))
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
        return {
            "parameters": tuple(StoredParameter.from_dict(p) for p in d["parameters"]),
            "root_min": np.asarray(d["root_min"], dtype=np.float64),
            "root_size": float(d["root_size"]),
            "lattice_depth": int(d["lattice_depth"]),
            "children": codec.decode(d["children"]),
            "corner_coords": codec.decode(d["corners"]),
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
