"""Store format 6's compact encodings (``service.store.format``, ``service.store.codec``): the same store
in fewer bytes, every decoded figure identical to format 5's.

- small integers (corner views, settings, frontier sizes and settings, camera counts) bit-packed at the
  fewest bits that hold them;
- the octree as one bit per node (split or not) where its children are in creation order, and no
  corner list where the corners are in the order the optimiser's lattice creates them;
- per-camera figures as what they add to the frontier's own worst figures: which camera holds each
  point's worst code and how far below it the other cameras' codes are.

Anything else (hand-built trees, corners in another order, per-camera figures whose largest is not the
stored worst) is written as format 5 wrote it, and format-5 documents (``tests/data/store_v5_priced.json``
was written by the format-5 writer before these encodings) still load."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.octree.lattice import Lattice
from service.store import (
    FORMAT_VERSION,
    READABLE_VERSIONS,
    Frontier,
    ParetoStore,
    StoredParameter,
    pack_array,
)
from service.store import format as store_format
from service.store.codec import decode, encode_bits, quantise_directions, quantise_eyes
from service.store.priced import PricedFigures

PARAMS = (StoredParameter("a", tuple(range(16)), 15), StoredParameter("b", tuple(range(8)), 7),
          StoredParameter("c", (0.25, 0.5, 0.75, 1.0), 3))
FPS = 30.0
V5_DOCUMENT = Path(__file__).parent / "data" / "store_v5_priced.json"


def path_like_store(seed: int, *, max_depth: int = 4, frontiers: int = 40, cameras: int = 2,
                    worst_is_max: bool = True, split_share: float = 0.4, frame_times: bool = False
                    ) -> ParetoStore:
    """A store shaped like a path-sampled one: an octree split by the optimiser's lattice (random nodes
    at each depth), ``frontiers`` frontiers of 5-16 points with frame times (some missing ``FPS``), each
    priced at ``cameras`` cameras (one in twenty at its sample camera only), with each camera's frame
    times too when ``frame_times``. With ``worst_is_max`` the frontier's figures are, as the path sampler
    keeps them, the worst over its cameras; otherwise the cameras' figures are anything at or below
    them."""
    rng = np.random.default_rng(seed)
    root_min, root_size = np.array([-12.0, -9.0, 0.5]), 24.0
    lat = Lattice(root_min, root_size, max_depth)
    lat.add_root()
    level = [0]
    for depth in range(1, max_depth + 1):
        split = [n for n in level if rng.random() < split_share] or level[:1]
        level = lat.split(split, depth)
    frs, priced = [], []
    for _ in range(frontiers):
        n = int(rng.integers(5, 17))
        idx = np.stack([rng.choice(16, n, replace=False), rng.integers(0, 8, n), rng.integers(0, 4, n)], 1)
        err = np.sort(rng.uniform(0.0, 0.4, n))[::-1]
        err[-1] = 0.0
        fr = Frontier.from_points(pack_array(idx), err, np.sort(rng.uniform(10.0, 60.0, n)),
                                  rng.uniform(0.005, 0.06, n), FPS)
        frs.append(fr)
        k = cameras if rng.random() < 0.95 else 1
        m = len(fr)
        de = rng.exponential(0.01, (k, m)) * (rng.random((k, m)) < 0.9)
        dp = rng.exponential(2.0, (k, m)) * (rng.random((k, m)) < 0.9)
        dt = rng.exponential(0.01, (k, m)) * (rng.random((k, m)) < 0.8) if frame_times else None
        if worst_is_max:  # one camera holds each point's worst figures
            at = rng.integers(0, k, m)
            de[at, np.arange(m)] = 0.0
            dp[at, np.arange(m)] = 0.0
            if dt is not None:
                dt[rng.integers(0, k, m), np.arange(m)] = 0.0
        eyes = quantise_eyes(rng.uniform(root_min, root_min + root_size, (k, 3)), root_min, root_size)
        fwd = quantise_directions(rng.normal(size=(k, 3)), fine=True)
        times = None if dt is None else np.clip(fr.frame_time_s[None, :] - dt, 0.0, None)
        priced.append(PricedFigures(eyes, fwd, float(rng.uniform(1.0, 20.0)), fr.packed,
                                    np.clip(fr.error[None, :] - de, 0.0, 1.0),
                                    np.clip(fr.power_w[None, :] - dp, 0.0, None), times))
    corners = len(lat.corner_coords)
    views = rng.integers(0, frontiers, (corners, 6))
    views.reshape(-1)[:frontiers] = np.arange(frontiers)  # every frontier read somewhere
    return ParetoStore(PARAMS, root_min, root_size, max_depth, np.asarray(lat.children),
                       np.asarray(lat.corner_coords, dtype=np.int64), views, frs, fps=FPS, profile="desktop",
                       meta={"static_power_w": 15.0}, frontier_eyes=np.vstack([pf.eyes[0] for pf in priced]),
                       frontier_dirs=np.vstack([pf.forwards[0] for pf in priced]), priced=priced)


def assert_identical(a: ParetoStore, b: ParetoStore) -> None:
    """Every decoded array of two stores equal, bit for bit."""
    for name in ("children", "corner_coords", "corner_views", "frontier_eyes", "frontier_dirs"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for x, y in zip(a.frontiers, b.frontiers, strict=True):
        for name in ("packed", "error", "power_w", "frame_time_s"):
            assert np.array_equal(getattr(x, name), getattr(y, name)), name
    assert (a.priced is None) == (b.priced is None)
    for x, y in zip(a.priced or [], b.priced or [], strict=True):
        assert (x is None) == (y is None)
        if x is not None:
            assert x.scale == y.scale
            for name in ("eyes", "forwards", "packed", "error", "power_w"):
                assert np.array_equal(getattr(x, name), getattr(y, name)), name
            assert (x.frame_time_s is None) == (y.frame_time_s is None)
            assert x.frame_time_s is None or np.array_equal(x.frame_time_s, y.frame_time_s)


# ------------------------------------------------------------------------------------------ bit packing


@settings(max_examples=150, deadline=None)
@given(st.lists(st.integers(0, 2**32 - 1), max_size=60), st.integers(0, 31))
def test_bit_packed_integers_come_back_exactly(values: list[int], extra: int) -> None:
    text = encode_bits(values)
    got = decode(text)
    assert got.dtype == np.int64 and got.tolist() == values
    width = int(text.split(":")[0][1:])
    assert width == max(1, max(values, default=0).bit_length())  # the fewest bits that hold them
    whole_bytes = (len(values) * width + 7) // 8
    assert len(text.split(":")[2]) == 4 * ((whole_bytes + 2) // 3)
    wider = min(32, width + extra)
    assert decode(encode_bits(values, wider)).tolist() == values


@pytest.mark.parametrize("text", [
    "b0:1:AA==",  # no width
    "b33:1:AAAAAAA=",  # wider than 32 bits
    "b3:4:HQ==",  # one byte short
    "b3:4:HQ4A",  # one byte too many
    "b3:4:HY4=",  # set padding bits
    "b3:x:HQ4=",  # count not a number
    "b3:-4:HQ4=",
    "bx:4:HQ4=",
    "b3:4:!!",
])
def test_corrupt_bit_packed_arrays_are_refused(text: str) -> None:
    assert decode("b3:4:HQ4=").tolist() == [5, 3, 0, 7]
    with pytest.raises(ValueError):
        decode(text)


def test_bit_packing_refuses_what_it_cannot_hold() -> None:
    for values, width in (([-1], None), ([8], 3), ([2**32], None), ([1], 0), ([0.5], None)):
        with pytest.raises(ValueError):
            encode_bits(values, width)


# ------------------------------------------------------------------------------------- the compact store


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), max_depth=st.integers(0, 4), frontiers=st.integers(1, 30),
       cameras=st.integers(1, 3), worst_is_max=st.booleans(), split_share=st.floats(0.0, 1.0),
       frame_times=st.booleans())
def test_re_encoding_keeps_every_figure(seed: int, max_depth: int, frontiers: int, cameras: int,
                                        worst_is_max: bool, split_share: float, frame_times: bool) -> None:
    """Format 6 decodes to exactly what format 5 decodes to (both hold the same 16-bit codes), the
    document is stable once written, it writes each per-camera figure in one form (the split where the
    store allows it and it is shorter: tests below), and it is shorter than format 5."""
    store = path_like_store(seed, max_depth=max_depth, frontiers=frontiers, cameras=cameras,
                            worst_is_max=worst_is_max, split_share=split_share, frame_times=frame_times)
    text5, text6 = store_format.to_json(store, 5), store.to_json()
    old, new = ParetoStore.from_json(text5), ParetoStore.from_json(text6)
    assert_identical(old, new)
    assert new.to_json() == text6 and store_format.to_json(new, 5) == text5
    doc = json.loads(text6)
    assert doc["version"] == FORMAT_VERSION == 6
    assert "node_splits" in doc and "children" not in doc and "corners" not in doc  # the lattice's order
    for name in ("error", "power", "frame_time"):
        split = {f"priced_{name}_worst", f"priced_{name}_below"} & set(doc)
        assert len(split) in (0, 2) and not (split and f"priced_{name}" in doc)
        assert bool(split or f"priced_{name}" in doc) == (name != "frame_time" or frame_times)
    assert len(text6) < len(text5)


def test_the_per_camera_split_is_written_where_it_is_shorter() -> None:
    """A store of 40 frontiers priced at 2 cameras takes the split for every figure; in one of a single
    point its second field costs more than it saves (written split, this store's document was 1158 bytes
    against format 5's 1145), and every figure keeps format 5's form."""
    for kw, split_names in ((dict(seed=7), ("error", "power", "frame_time")),
                            (dict(seed=69893674, max_depth=0, frontiers=1), ())):
        store = path_like_store(**kw, cameras=2, worst_is_max=True, split_share=0.0, frame_times=True)
        doc = store.to_dict()
        for name in ("error", "power", "frame_time"):
            split = {f"priced_{name}_worst", f"priced_{name}_below"} <= set(doc)
            assert split == (name in split_names) and split != (f"priced_{name}" in doc)
        text5, text6 = store_format.to_json(store, 5), store.to_json()
        assert len(text6) < len(text5)
        assert_identical(ParetoStore.from_json(text5), ParetoStore.from_json(text6))


def test_the_compact_forms_fall_back_to_format_5s_where_a_store_does_not_allow_them() -> None:
    """Per-camera figures whose largest is not the stored worst (per figure), a tree split out of
    creation order and corners in another order are written as format 5 wrote them, and read back."""
    store = path_like_store(7, max_depth=2, frontiers=6, cameras=2)
    pf = store.priced[0]
    lower = PricedFigures(pf.eyes, pf.forwards, pf.scale, pf.packed, pf.error - 0.01 * (pf.error > 0.01),
                          pf.power_w)  # errors below the stored worst at every camera
    mixed = dataclasses.replace(store, priced=[lower, *store.priced[1:]])
    doc = mixed.to_dict()
    assert "priced_error" in doc and "priced_error_worst" not in doc
    assert "priced_power_worst" in doc and "priced_power" not in doc
    assert_identical(ParetoStore.from_json(store_format.to_json(mixed, 5)), ParetoStore.from_dict(doc))

    # two nodes split in the reverse of their order: children[1] > children[2]
    lat = Lattice(np.zeros(3), 2.0, 2)
    lat.add_root()
    lat.split([0], 1)
    lat.split([2, 1], 2)
    ch, coords = np.asarray(lat.children), np.asarray(lat.corner_coords, dtype=np.int64)
    assert ch[1] > ch[2] > 0
    views = np.zeros((coords.shape[0], 6), dtype=np.int64)
    flat = ParetoStore(PARAMS, np.zeros(3), 2.0, 2, ch, coords, views, store.frontiers[:1])
    doc = flat.to_dict()
    assert "children" in doc and "node_splits" not in doc and "corners" not in doc
    back = ParetoStore.from_dict(doc)
    assert np.array_equal(back.children, ch) and np.array_equal(back.corner_coords, coords)

    shuffled = dataclasses.replace(store, corner_coords=store.corner_coords[::-1].copy())
    doc = shuffled.to_dict()
    assert "node_splits" in doc and decode(doc["corners"]).reshape(-1, 3).tolist() == \
        shuffled.corner_coords.tolist()
    assert np.array_equal(ParetoStore.from_dict(doc).corner_coords, shuffled.corner_coords)


def test_the_lattice_corner_order_is_the_optimisers() -> None:
    """:func:`lattice_corners` derives the corners the optimiser's lattice creates, split by split."""
    lat = Lattice(np.zeros(3), 16.0, 4)
    lat.add_root()
    level = lat.split([0], 1)
    level = lat.split(level[::3], 2)
    lat.split([level[1], level[6], level[-1]], 3)
    derived = store_format.lattice_corners(np.asarray(lat.children), 4)
    assert derived.tolist() == [list(c) for c in lat.corner_coords]
    with pytest.raises(ValueError, match="deeper"):
        store_format.lattice_corners(np.asarray(lat.children), 2)


def test_a_store_of_a_known_shape_is_a_third_smaller() -> None:
    """A path-sampled store's shape (depth-4 octree, 40 frontiers of 5-16 points priced at 2 cameras):
    format 6 takes at most two thirds of format 5's bytes (the real stores: bench/RESULTS.md, "The
    store's size with per-camera figures")."""
    store = path_like_store(11)
    text5, text6 = store_format.to_json(store, 5), store.to_json()
    assert len(text6) <= 0.67 * len(text5), (len(text6), len(text5))
    doc5, doc6 = json.loads(text5), json.loads(text6)
    priced5 = sum(len(doc5[k]) for k in ("priced_error", "priced_power"))
    priced6 = sum(len(doc6[k]) for k in doc6 if k.startswith(("priced_error", "priced_power")))
    assert priced6 <= 0.5 * priced5  # the other camera of each point, below the worst figure


def test_a_format_5_document_still_loads_and_reads_the_same() -> None:
    """A document the format-5 writer wrote (before the compact encodings) loads; written again as
    format 5 it is the same bytes, and as format 6 it decodes to the same store."""
    text = V5_DOCUMENT.read_text().strip()
    assert json.loads(text)["version"] == 5 and 5 in READABLE_VERSIONS
    store = ParetoStore.from_json(text)
    assert store.priced is not None and any(pf.cameras == 2 for pf in store.priced)
    assert store_format.to_json(store, 5) == text
    again = ParetoStore.from_json(store.to_json())
    assert_identical(store, again)
    for eye, fwd in zip(store.frontier_eyes, store.frontier_dirs, strict=True):
        for budget in ({"error_budget": 0.02}, {"power_budget": 40.0}):
            assert again.lookup(eye, direction=fwd, **budget) == store.lookup(eye, direction=fwd, **budget)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), cameras=st.integers(1, 3), worst_is_max=st.booleans())
def test_per_camera_frame_times_come_back_on_their_side_of_the_frame_period(seed: int, cameras: int,
                                                                           worst_is_max: bool) -> None:
    """Each point's frame time at each pricing camera comes back within a step of the frontiers' frame
    time steps, never across the frame period (a camera where a setting keeps up still keeps up after a
    round trip, and one where it misses still misses), and never above the point's stored (worst) one
    when that is the largest of them."""
    store = path_like_store(seed, max_depth=2, frontiers=12, cameras=cameras, worst_is_max=worst_is_max,
                            frame_times=True)
    back = ParetoStore.from_json(store.to_json())
    step = float(store.to_dict()["frame_time_scale"]) / 65535
    period = 1.0 / FPS
    for a, b, fr in zip(store.priced, back.priced, back.frontiers, strict=True):
        assert b.frame_time_s.shape == a.frame_time_s.shape
        assert np.all((a.frame_time_s <= period) == (b.frame_time_s <= period))
        assert np.allclose(a.frame_time_s, b.frame_time_s, atol=2 * step)
        if worst_is_max:
            assert np.array_equal(b.frame_time_s.max(axis=0), fr.frame_time_s)


def test_a_store_without_per_camera_frame_times_is_written_as_before() -> None:
    """Per-camera frame times add their own fields only: the same store without them writes every other
    field as it did, and a document without them reads as a store without them (the lookup then draws
    its tiers from the stored frame times, as before: tests/test_priced_frame_times.py)."""
    timed = path_like_store(5, max_depth=2, frontiers=10, frame_times=True)
    plain = dataclasses.replace(timed, priced=[dataclasses.replace(pf, frame_time_s=None)
                                               for pf in timed.priced])
    a, b = timed.to_dict(), plain.to_dict()
    assert {k: v for k, v in a.items() if not k.startswith("priced_frame_time")} == b
    assert not plain.priced_frame_times_known and timed.priced_frame_times_known
    back = ParetoStore.from_dict(b)
    assert all(pf.frame_time_s is None for pf in back.priced)
    for version in (5, 6):
        d = store_format.to_dict(timed, version)
        assert ParetoStore.from_dict(d).priced_frame_times_known


def test_per_camera_frame_times_need_frame_times_for_every_priced_frontier() -> None:
    timed = path_like_store(5, max_depth=1, frontiers=4, frame_times=True)
    mixed = [timed.priced[0], *(dataclasses.replace(pf, frame_time_s=None) for pf in timed.priced[1:])]
    with pytest.raises(ValueError, match="every priced frontier"):
        dataclasses.replace(timed, priced=mixed)
    untimed = [dataclasses.replace(f, frame_time_s=None) for f in timed.frontiers]
    with pytest.raises(ValueError, match="frontiers' frame times"):
        dataclasses.replace(timed, frontiers=untimed)
    pf = timed.priced[0]
    with pytest.raises(ValueError, match="frame times"):
        dataclasses.replace(pf, frame_time_s=np.full_like(pf.error, -1.0))


@pytest.mark.parametrize("mutate", [
    lambda d: d.update(priced_frame_time_worst=encode_bits([5] * decode(d["priced_frame_time_worst"]).size)),
    lambda d: d.update(priced_frame_time_below=encode_bits(decode(d["priced_frame_time_below"])[:-1])),
    lambda d: d.update(priced_frame_time_below=encode_bits(
        np.full(decode(d["priced_frame_time_below"]).size, 65535))),
    lambda d: d.pop("priced_frame_time_below"),
    lambda d: d.pop("frontier_frame_time"),
])
def test_corrupt_per_camera_frame_times_are_refused(mutate) -> None:
    d = path_like_store(3, max_depth=2, frontiers=8, frame_times=True).to_dict()
    ParetoStore.from_dict(d)
    mutate(d)
    with pytest.raises(ValueError):
        ParetoStore.from_dict(d)


@pytest.mark.parametrize("mutate", [
    lambda d: d.update(children="<i4://///w=="),  # the octree twice
    lambda d: d.update(node_splits=encode_bits([1] + [0] * 7)),  # 8 nodes: not 1 + 8 per split
    lambda d: d.update(node_splits=encode_bits([0] * 8 + [1] + [0] * 8)),  # split before it exists
    lambda d: d.update(node_splits=encode_bits([2] + [0] * 8)),
    lambda d: d.update(priced_error_worst=encode_bits([5] * decode(d["priced_error_worst"]).size)),
    lambda d: d.update(priced_power_below=encode_bits(decode(d["priced_power_below"])[:-1])),
    lambda d: d.update(priced_error_below=encode_bits(np.full(decode(d["priced_error_below"]).size, 65535))),
    lambda d: d.pop("priced_power_worst"),
    lambda d: d.update(version=FORMAT_VERSION + 1),
])
def test_corrupt_compact_documents_are_refused(mutate) -> None:
    d = path_like_store(3, max_depth=2, frontiers=8).to_dict()
    ParetoStore.from_dict(d)
    mutate(d)
    with pytest.raises(ValueError):
        ParetoStore.from_dict(d)


def test_only_known_versions_are_written() -> None:
    store = path_like_store(3, max_depth=1, frontiers=2)
    for version in (4, 7):
        with pytest.raises(ValueError, match="version"):
            store_format.to_dict(store, version)
