"""Energy and timing model: profiles, pricing invariants on counter sets (render-based ones are in
test_energy_render.py)."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
import sim_core.energy as energy
from hypothesis import given, settings
from hypothesis import strategies as st
from sim_core.energy import BLOCKS, list_profiles, load_profile, price

COUNTERS = {
    "rays_primary": 2_000_000, "rays_shadow": 1_500_000, "rays_total": 3_500_000,
    "raygen_evals": 2_000_000, "shading_evals": 2_000_000, "bvh_node_visits": 90_000_000,
    "triangle_tests": 20_000_000, "cache_accesses": 50_000_000, "cache_misses": 900_000,
    "dram_bytes_read": 57_600_000, "tile_buffer_reads": 4_000_000, "tile_buffer_writes": 2_000_000,
    "framebuffer_bytes": 8_388_608, "pixels": 2_097_152,
}


#: Every shipped profile: the per-profile tests below run over each one added.
SHIPPED = list_profiles()


def test_shipped_profiles_load_and_are_listed() -> None:
    names = list_profiles()
    assert {"mobile", "desktop", "desktop_gtx980"} <= set(names)
    for name in names:
        p = load_profile(name)
        assert p.name == name and p.static_power_w > 0
        cfg = p.cache
        assert cfg.size_bytes == p.cache_size_bytes and cfg.ways == p.cache_ways
    mobile = load_profile("mobile")
    assert 0.5e9 <= mobile.clock["srp_hz"] <= 1.5e9  # "~1 GHz" SGRT-like


def test_every_profile_constant_carries_a_comment() -> None:
    for path in Path(energy.__file__).with_name("profiles").glob("*.toml"):
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if re.match(r"^\s*[a-z_0-9]+\s*=\s*[-0-9.]", line):
                assert "#" in line, f"{path.name}:{i} has no source/assumption comment: {line!r}"


def test_load_profile_by_path_and_errors(tmp_path: Path) -> None:
    src = Path(energy.__file__).with_name("profiles") / "mobile.toml"
    assert load_profile(src).name == "mobile"
    with pytest.raises(FileNotFoundError):
        load_profile("no-such-profile")
    broken = tmp_path / "broken.toml"
    broken.write_text(src.read_text().replace("traversal_step = 100.0", "traversal_step = -1.0"))
    with pytest.raises(ValueError, match="traversal_step"):
        load_profile(broken)
    missing = tmp_path / "missing.toml"
    missing.write_text(src.read_text().replace("ways = 4", ""))
    with pytest.raises(ValueError, match="ways"):
        load_profile(missing)
    odd = tmp_path / "odd.toml"
    odd.write_text(src.read_text().replace("line_bytes = 64", "line_bytes = 48"))
    with pytest.raises(ValueError, match="power-of-two"):
        load_profile(odd)


@pytest.mark.parametrize("profile", SHIPPED)
@pytest.mark.parametrize("fps", [24.0, 60.0])
def test_total_is_sum_of_blocks_and_power_is_static_plus_e_fps(profile: str, fps: float) -> None:
    small = {k: v // 100 for k, v in COUNTERS.items()}  # a frame well inside its deadline
    r = price(small, profile, fps)
    assert r.deadline_met  # priced at the target frame rate
    assert set(r.energy_j) == set(BLOCKS) | {"static"}
    assert r.total_energy_j == pytest.approx(math.fsum(r.energy_j.values()), rel=1e-12)
    assert r.dynamic_energy_j == pytest.approx(r.total_energy_j - r.energy_j["static"], rel=1e-12)
    p = load_profile(profile)
    assert r.achieved_fps == fps
    assert r.power_w == pytest.approx(p.static_power_w + r.dynamic_energy_j * fps, rel=1e-12)
    assert r.power_w == pytest.approx(r.total_energy_j * fps, rel=1e-12)
    assert r.frame_time_s == pytest.approx(max(r.unit_time_s.values()))
    assert r.deadline_met == (r.frame_time_s <= 1 / fps)
    assert r.mrays_per_s == pytest.approx(small["rays_total"] / r.frame_time_s / 1e6)
    assert r.perf_per_watt == pytest.approx(r.max_fps / r.power_full_speed_w)


def test_unused_blocks_cost_exactly_zero() -> None:
    r = price(COUNTERS, "mobile", 30.0)
    unused = ("similarity", "interpolation", "reprojection", "env_filter", "gbuffer_prefetch", "comparator")
    for block in unused:
        assert r.energy_j[block] == 0.0 and r.cycles[block] == 0.0
    assert set(r.blocks_used) == {"raygen", "shading", "traversal", "intersection", "cache", "tile_buffer",
                                  "dram", "framebuffer_dma"}
    nothing = price({}, "mobile", 30.0)
    assert nothing.dynamic_energy_j == 0.0 and nothing.power_w == load_profile("mobile").static_power_w


def test_each_counter_moves_only_its_block() -> None:
    base = price(COUNTERS, "mobile", 30.0)
    for counter, block in [("similarity_checks", "similarity"), ("interpolations", "interpolation"),
                           ("reprojections", "reprojection"), ("gbuffer_prefetch_bytes", "gbuffer_prefetch"),
                           ("env_lookups", "env_filter"), ("env_filtered_lookups", "env_filter")]:
        r = price({**COUNTERS, counter: 1000}, "mobile", 30.0)
        changed = {b for b in BLOCKS if r.energy_j[b] != base.energy_j[b]}
        assert changed == {block}, (counter, changed)


@pytest.mark.parametrize("profile", SHIPPED)
def test_a_node_visit_is_one_wide_node_step(profile: str) -> None:
    """bvh_node_visits counts 4-wide node steps: priced per step, timed as four box tests each."""
    from sim_core import _core

    assert _core.BVH_NODE_BOXES == 4 and _core.BVH_NODE_BYTES == 128 and _core.TRIANGLE_RECORD_BYTES == 48
    p = load_profile(profile)
    r = price({"bvh_node_visits": 1000}, p, 30.0)
    assert r.energy_j["traversal"] == pytest.approx(1000 * p.energy_pj["traversal_step"] * 1e-12, rel=1e-12)
    steps_per_cycle = p.throughput["ti_box_tests_per_cycle"] / 4
    assert r.cycles["traversal"] == pytest.approx(1000 / steps_per_cycle, rel=1e-12)


def test_the_gtx980_profile_is_the_desktop_part_wider() -> None:
    """Same architecture and process as ``desktop``: every event costs the same energy, only the units,
    clock, bandwidth and static power differ, so a frame's dynamic energy is equal and it runs 3.2 x
    1.126 times faster where a core-bound unit is the bottleneck (DRAM is 2.8x wider)."""
    desktop, wide = load_profile("desktop"), load_profile("desktop_gtx980")
    assert wide.energy_pj == desktop.energy_pj and wide.ops == desktop.ops
    assert wide.cache_size_bytes == desktop.cache_size_bytes
    assert wide.comparator_style == desktop.comparator_style
    for key, value in desktop.throughput.items():
        ratio = wide.throughput[key] / value
        assert ratio == pytest.approx(224 / 80 if key == "dram_bytes_per_s" else 3.2), key
    rd, rw = price(COUNTERS, desktop, 30.0), price(COUNTERS, wide, 30.0)
    assert rw.dynamic_energy_j == pytest.approx(rd.dynamic_energy_j, rel=1e-12)
    speedup = rd.frame_time_s / rw.frame_time_s
    assert 2.8 * 1.126 * (1 - 1e-9) <= speedup <= 3.2 * 1.126 * (1 + 1e-9)
    assert wide.static_power_w / 165 == pytest.approx(desktop.static_power_w / 68, rel=0.02)


def test_dynamic_energy_is_linear_in_activity() -> None:
    r1 = price(COUNTERS, "mobile", 30.0)
    r2 = price({k: 2 * v for k, v in COUNTERS.items()}, "mobile", 30.0)
    assert r2.dynamic_energy_j == pytest.approx(2 * r1.dynamic_energy_j, rel=1e-12)
    assert r2.frame_time_s == pytest.approx(2 * r1.frame_time_s, rel=1e-12)


def test_comparator_block_uses_the_profile_style() -> None:
    hist = np.zeros(25, dtype=np.int64)
    hist[[0, 3, 8]] = [100, 50, 25]

    class Result:  # what the tracer's RenderResult exposes to the pricer
        def __init__(self) -> None:
            self.counters = {**COUNTERS, "closest_hit_comparisons": 175}
            self.comparator_histogram = hist

    mobile, desktop = load_profile("mobile"), load_profile("desktop")
    rm, rd = price(Result(), mobile, 30), price(Result(), desktop, 30)
    assert mobile.comparator_style == "async" and desktop.comparator_style == "sync"
    assert rm.energy_j["comparator"] == pytest.approx(rm.comparator.async_energy_j)
    assert rd.energy_j["comparator"] == pytest.approx(rd.comparator.sync_energy_j)
    assert rm.comparator.comparisons == 175
    assert rm.comparator.average_chain_length == pytest.approx((3 * 50 + 8 * 25) / 175)


def test_bad_input_is_rejected() -> None:
    with pytest.raises(ValueError):
        price(COUNTERS, "mobile", 0.0)
    with pytest.raises(ValueError):
        price(COUNTERS, "mobile", float("nan"))
    with pytest.raises(ValueError):
        price({**COUNTERS, "rays_total": -1}, "mobile", 30)
    with pytest.raises(ValueError):
        price({**COUNTERS, "rays_total": 1.5}, "mobile", 30)
    with pytest.raises(ValueError):  # comparisons counted but no histogram to price them
        price({**COUNTERS, "closest_hit_comparisons": 10}, "mobile", 30)


_counts = st.integers(min_value=0, max_value=10**10)


@pytest.mark.parametrize("profile", SHIPPED)
@settings(max_examples=80, deadline=None)
@given(counters=st.dictionaries(st.sampled_from(energy.COUNTERS[:-1]), _counts, max_size=12),
       fps=st.floats(min_value=0.5, max_value=480.0))
def test_no_reported_power_exceeds_the_full_speed_power(profile: str, counters: dict[str, int],
                                                        fps: float) -> None:
    counters = {k: v for k, v in counters.items() if k != "closest_hit_comparisons"}
    r = price(counters, profile, fps)
    static = load_profile(profile).static_power_w
    assert static <= r.power_w <= r.power_full_speed_w
    assert r.achieved_fps <= fps and (r.frame_time_s == 0 or r.achieved_fps <= r.max_fps)
    if r.deadline_met:  # exactly as before the frame rate was taken into account
        assert r.achieved_fps == fps
        assert r.power_w == pytest.approx(static + r.dynamic_energy_j * fps, rel=1e-12)
    else:  # at its own frame rate: running flat out
        assert r.achieved_fps == pytest.approx(r.max_fps, rel=1e-12)
        assert r.power_w == r.power_full_speed_w


@settings(max_examples=200, deadline=None)
@given(static=st.floats(min_value=0.0, max_value=100.0), dynamic=st.floats(min_value=0.0, max_value=1e3),
       frame_time=st.floats(min_value=0.0, max_value=1e3), fps=st.floats(min_value=1e-3, max_value=1e4))
def test_sustained_power_is_bounded_by_full_speed_and_target(static: float, dynamic: float,
                                                              frame_time: float, fps: float) -> None:
    power, rate = energy.sustained_power(static, dynamic, frame_time, fps)
    assert rate <= fps
    assert power <= static + dynamic * fps
    if frame_time > 0:
        assert rate <= 1.0 / frame_time
        assert power <= static + dynamic / frame_time  # never above the full-speed power
    if frame_time <= 1.0 / fps:  # the deadline is met: the target frame rate, as before
        assert rate == fps
        assert power == pytest.approx(static + dynamic * fps, rel=1e-12)
    else:
        assert rate == 1.0 / frame_time
        assert power == static + dynamic / frame_time


def test_a_frame_that_misses_its_deadline_is_priced_at_its_own_rate() -> None:
    slow = {k: v * 10**4 for k, v in COUNTERS.items()}
    r = price(slow, "mobile", 30.0)
    assert not r.deadline_met and r.max_fps < 30.0
    assert r.achieved_fps == r.max_fps
    assert r.power_w == r.power_full_speed_w
    assert r.power_w < load_profile("mobile").static_power_w + r.dynamic_energy_j * 30.0
    assert r.energy_j["static"] == pytest.approx(load_profile("mobile").static_power_w * r.frame_time_s)
    for bad in (float("nan"), -1.0, float("inf")):
        with pytest.raises(ValueError):
            energy.sustained_power(0.25, 1.0, bad, 30.0)
    with pytest.raises(ValueError):
        energy.sustained_power(0.25, 1.0, 0.1, 0.0)


@settings(max_examples=60, deadline=None)
@given(counters=st.dictionaries(st.sampled_from(energy.COUNTERS[:-1]), _counts, max_size=12),
       fps=st.floats(min_value=1.0, max_value=240.0), scale=st.integers(min_value=1, max_value=7))
def test_pricing_invariants_hold_for_any_counters(counters: dict[str, int], fps: float, scale: int) -> None:
    counters = {k: v for k, v in counters.items() if k != "closest_hit_comparisons"}
    r = price(counters, "mobile", fps)
    assert r.total_energy_j == pytest.approx(math.fsum(r.energy_j.values()), rel=1e-9, abs=1e-18)
    static = load_profile("mobile").static_power_w
    # power at the frame rate the GPU reaches: the target when the frame meets its deadline, else its own
    rate = fps if r.deadline_met else 1.0 / r.frame_time_s
    assert r.achieved_fps == pytest.approx(rate, rel=1e-12)
    assert r.power_w == pytest.approx(static + r.dynamic_energy_j * rate, rel=1e-9)
    assert r.power_w <= r.power_full_speed_w
    assert r.power_w == pytest.approx(r.total_energy_j * r.achieved_fps, rel=1e-9)
    assert all(v >= 0 for v in r.energy_j.values()) and all(v >= 0 for v in r.cycles.values())
    for b in BLOCKS:  # a block with no activity costs exactly nothing
        if r.cycles[b] == 0 and b != "comparator":
            assert r.energy_j[b] == 0.0
    scaled = price({k: v * scale for k, v in counters.items()}, "mobile", fps)
    assert scaled.dynamic_energy_j == pytest.approx(scale * r.dynamic_energy_j, rel=1e-9, abs=1e-18)
    assert scaled.frame_time_s == pytest.approx(scale * r.frame_time_s, rel=1e-9, abs=1e-18)


@pytest.mark.parametrize("style", ["sync", "async"])
@settings(max_examples=40, deadline=None)
@given(tiles=st.lists(st.tuples(st.dictionaries(st.sampled_from(energy.COUNTERS), _counts, max_size=14),
                                st.lists(st.integers(0, 10**6), min_size=25, max_size=25)),
                      min_size=1, max_size=6),
       env=st.sampled_from(["box", "bartlett", "off"]))
def test_tiles_priced_at_once_equal_each_tile_priced_alone(style: str, tiles, env: str) -> None:
    """price_tiles is price's arithmetic on arrays: every tile's dynamic energy equal to rounding, for any
    counters (missing ones count 0), histograms, comparator style and environment filter."""
    from types import SimpleNamespace

    prof = dataclasses.replace(load_profile("mobile"), comparator_style=style)
    settings_ = SimpleNamespace(env_filter=env)
    rows = []
    for counters, hist in tiles:
        h = np.asarray(hist, dtype=np.int64)
        if h.sum() == 0:
            counters = {k: v for k, v in counters.items() if k != "closest_hit_comparisons"}
        rows.append((counters, h))
    alone = [price(SimpleNamespace(counters=c, comparator_histogram=h, settings=settings_), prof,
                   30.0).dynamic_energy_j for c, h in rows]
    names = sorted({k for c, _ in rows for k in c})
    columns = {k: np.array([c.get(k, 0) for c, _ in rows], dtype=np.uint64) for k in names}
    if not columns:
        columns = {"pixels": np.zeros(len(rows), dtype=np.uint64)}
    at_once = energy.price_tiles(columns, np.stack([h for _, h in rows]), prof, settings=settings_)
    np.testing.assert_allclose(at_once, alone, rtol=1e-12, atol=0)


def test_price_tiles_rejects_bad_input() -> None:
    one = {"rays_total": np.array([1, 2], dtype=np.uint64)}
    with pytest.raises(ValueError, match="one count per tile"):
        energy.price_tiles({**one, "pixels": np.array([1])}, None, "mobile")
    with pytest.raises(ValueError, match="integers"):
        energy.price_tiles({"rays_total": np.array([1.5, 2.0])}, None, "mobile")
    with pytest.raises(ValueError, match="negative"):
        energy.price_tiles({"rays_total": np.array([1, -2])}, None, "mobile")
    with pytest.raises(ValueError, match="histograms"):
        energy.price_tiles(one, np.zeros((3, 25), np.int64), "mobile")
    with pytest.raises(ValueError, match="no comparator histogram"):
        energy.price_tiles({"closest_hit_comparisons": np.array([0, 5])}, np.zeros((2, 25), np.int64),
                           "mobile")
    with pytest.raises(ValueError, match="at least one"):
        energy.price_tiles({}, None, "mobile")


def test_a_profile_takes_what_it_does_not_set_from_its_base(tmp_path: Path) -> None:
    desktop = load_profile("desktop")
    child = tmp_path / "child.toml"
    child.write_text('base = "desktop"\nname = "child"\n[static]\npower_w = 20.0  # test\n'
                     '[throughput]\nsrp_ops_per_cycle = 1280  # test\n')
    p = load_profile(child)
    assert p.name == "child" and p.static_power_w == 20.0 and p.throughput["srp_ops_per_cycle"] == 1280
    # the rest of an overridden section, and whole sections it does not name, come from the base
    assert p.throughput["dram_bytes_per_s"] == desktop.throughput["dram_bytes_per_s"]
    assert p.energy_pj == desktop.energy_pj and p.ops == desktop.ops and p.cache_ways == desktop.cache_ways
    grandchild = tmp_path / "grandchild.toml"  # a base by path, relative to the file naming it
    grandchild.write_text('base = "child.toml"\nname = "grandchild"\n[clock]\nsrp_hz = 2e9  # test\n')
    g = load_profile(grandchild)
    assert g.static_power_w == 20.0 and g.clock["srp_hz"] == 2e9
    assert g.clock["ti_hz"] == desktop.clock["ti_hz"]
    loop = tmp_path / "loop.toml"
    loop.write_text('base = "loop.toml"\nname = "loop"\n')
    with pytest.raises(ValueError, match="cycle"):
        load_profile(loop)
    nameless = tmp_path / "nameless.toml"
    nameless.write_text('base = "desktop"\n')
    with pytest.raises(ValueError, match="own 'name'"):
        load_profile(nameless)
    orphan = tmp_path / "orphan.toml"
    orphan.write_text('base = "no-such-profile"\nname = "orphan"\n')
    with pytest.raises(FileNotFoundError, match="no-such-profile"):
        load_profile(orphan)
    child.write_text('base = "desktop"\nname = "child"\n[static]\npower_w = -1.0  # test\n')
    with pytest.raises(ValueError, match="power_w"):  # the merged profile is validated as a whole
        load_profile(child)


def test_the_fingerprint_follows_the_figures_not_the_name_or_file(tmp_path: Path) -> None:
    src = Path(energy.__file__).with_name("profiles") / "mobile.toml"
    copy = tmp_path / "copy.toml"
    copy.write_text(src.read_text().replace('name = "mobile"', 'name = "other"')
                    .replace('description = "', 'description = "Copied: '))
    assert load_profile(copy).fingerprint == load_profile("mobile").fingerprint
    copy.write_text(src.read_text().replace("traversal_step = 100.0", "traversal_step = 100.5"))
    assert load_profile(copy).fingerprint != load_profile("mobile").fingerprint
    assert len({load_profile(name).fingerprint for name in SHIPPED}) == len(SHIPPED)
