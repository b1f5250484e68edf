"""bench/bench_space_steps.py's neighbourhood of Max: the enumeration (count and distance), the merging of
settings a sampling mode renders alike, and the per-frame table's choices."""

from __future__ import annotations

import dataclasses
import itertools
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from tracer_scenes import teapot_scene

import sim_core
from service.params import default_space

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
import bench_space_steps as bss


def _all_distances(space):
    mq = space.max_quality_indices()
    free = space.free_positions
    out = []
    for t in itertools.product(*(range(len(p.values)) for p in space.parameters)):
        if any(t[i] != mq[i] for i in range(len(t)) if i not in free):
            continue
        out.append(sum(abs(a - b) for a, b in zip(t, mq, strict=True)))
    return out


@pytest.mark.parametrize("fixed", [(), ("env_filter", "multirate")])
def test_neighbourhood_counts_and_distances(fixed) -> None:
    space = default_space()
    if fixed:
        space = space.fix_inert({name: "inert" for name in fixed})
    dists = _all_distances(space)
    assert len(dists) == space.size
    far = max(dists)
    for k in range(far + 2):
        nb = bss.neighbourhood(space, k)
        assert len(nb) == sum(d <= k for d in dists)
        assert len(set(nb)) == len(nb)
        ds = [bss.distance(space, idx) for idx in nb]
        assert all(d <= k for d in ds) and ds == sorted(ds)
        for idx in nb:
            space.validate(idx)
            assert all(idx[space.names.index(name)] == space.max_quality_indices()[space.names.index(name)]
                       for name in fixed)
    assert bss.neighbourhood(space, 0) == [space.max_quality_indices()]
    assert len(bss.neighbourhood(space, far)) == space.size
    # one step: one setting a free parameter
    assert len(bss.neighbourhood(space, 1)) == 1 + len(space.free_positions)


def test_canonical_merges_only_what_the_mode_does_not_read() -> None:
    space = default_space()
    mx = space.to_settings(space.max_quality_indices())
    nt, mr = space.names.index("normal_threshold_deg"), space.names.index("multirate")
    samp = space.names.index("sampling")
    for s_i, mode_name in enumerate(space.parameters[samp].values):
        keys = set()
        for n_i, m_i in itertools.product(range(3), range(2)):
            idx = list(space.max_quality_indices())
            idx[samp], idx[nt], idx[mr] = s_i, n_i, m_i
            keys.add(bss._settings_key(bss.canonical(space.to_settings(idx), mx)))
        adaptive = mode_name.startswith(("undersample", "adaptive"))
        assert len(keys) == (6 if adaptive else 1), mode_name


@pytest.mark.parametrize("mode", ["fsaa", "1spp"])
def test_non_adaptive_modes_render_alike_whatever_the_threshold(mode) -> None:
    """What ``canonical`` relies on: the renderer does not read the threshold or multi-rate there."""
    scene = teapot_scene()
    cam = sim_core.Camera.look_at((0.0, -6.0, 3.0), (0.0, 0.0, 0.5), (0.0, 0.0, 1.0), math.radians(40.0),
                                  48, 27)
    base = dataclasses.replace(sim_core.RenderSettings.max_quality(), mode=mode, block=2)
    ref = sim_core.render(scene, cam, base, threads=1)
    for nt, mr in ((45.0, False), (5.0, True), (-1.0, True)):
        other = dataclasses.replace(base, normal_threshold_deg=nt, multirate=mr)
        r = sim_core.render(scene, cam, other, threads=1)
        assert np.array_equal(r.image, ref.image)
        assert dict(r.counters) == dict(ref.counters)


def _row(errors, powers, fps_list):
    return {"errors": errors, "powers": powers, "fps_per_camera": fps_list,
            "frame_times": [1.0 / f for f in fps_list]}


def test_neighbourhood_table_picks_per_frame() -> None:
    space = default_space()
    mq = space.max_quality_indices()
    shadow = space.names.index("shadow_samples")
    ao = space.names.index("ao_samples")
    s4 = tuple(v - (i == shadow) for i, v in enumerate(mq))
    a8 = tuple(v - (i == ao) for i, v in enumerate(mq))
    both = tuple(v - (i in (shadow, ao)) for i, v in enumerate(mq))
    rows = [
        (mq, _row([0.0, 0.0], [40.0, 38.0], [25.0, 30.0])),      # Max: slow at the first frame only
        (s4, _row([0.001, 0.03], [35.0, 30.0], [30.0, 30.0])),   # fast; over budget at the second
        (a8, _row([0.0005, 0.002], [37.0, 36.0], [28.0, 30.0])),  # slow at the first
        (both, _row([0.025, 0.01], [30.0, 29.0], [30.0, 30.0])),  # over budget at the first
    ]
    table = bss.neighbourhood_table(space, rows, [10, 20], 30.0, 0.02)
    first, second = table[2], table[3]
    assert first.startswith("| 10 | 25.0, 40.00 | 2 | 1 (1) | 12.5 %, 0.0010, 30.0, 35.00, "
                            "shadow_samples=4 |")
    assert first.endswith("| 0.0010, 35.00, shadow_samples=4 |")
    assert second.startswith("| 20 | 30.0, 38.00 | 4 | 3 (0) |")
    saved = 100.0 * (1.0 - 29.0 / 38.0)
    assert f"{saved:.1f} %, 0.0100, 30.0, 29.00, shadow_samples=4, ao_samples=8 |" in second
    assert second.endswith("| 0.0000, 38.00, Max |")
    none = bss.neighbourhood_table(space, rows[:1], [10], 30.0, 0.02)[2]
    assert none == "| 10 | 25.0, 40.00 | 0 | 0 | none | none |"
    assert math.isclose(bss.distance(space, both), 2)


def test_store_frontiers_agree_with_the_lookup(tmp_path) -> None:
    """``--store``: per frame the frontier the lookup reads, and real-time points within the budget
    exactly where the lookup (frame rate first) finds the budget feasible."""
    from service.camera_path import CameraPath
    from service.store.pareto import ParetoStore

    src = Path(__file__).resolve().parent / "data" / "store_v5_priced.json"
    store = ParetoStore.from_json(src.read_text())
    eyes, dirs = [], []
    for corner in range(store.corner_views.shape[0]):
        for view in range(store.corner_views.shape[1]):
            eye, forward, _ = store.sample_camera(corner, view)
            eyes.append(eye)
            dirs.append(forward)
    path = CameraPath.from_positions(eyes, dirs, vfov=store.vfov)
    frames = list(range(len(path)))
    for budget in (0.0, 0.05, 0.1, 0.12):
        rows = bss.store_frontiers(src, path, frames, budget)[2:]
        assert len(rows) == len(frames)
        for i, row in zip(frames, rows, strict=True):
            cells = [c.strip() for c in row.strip("|").split("|")]
            f = path.frames[i]
            m = np.asarray(f.matrix_world)
            hit = store.lookup(m[:3, 3], matrix=m, fov=f.vfov, error_budget=budget)
            assert cells[0] == str(i)
            assert cells[1].startswith(f"{hit.frontier} (")
            assert (int(cells[4]) > 0) == (bool(hit.meets_fps) and not hit.infeasible)


@pytest.fixture(scope="module")
def small_store(tmp_path_factory: pytest.TempPathFactory):
    """A store priced whole at its path's 96x72 (the teapot on an orbit, as tests/test_verify.py builds)."""
    from tests.test_verify import orbit_store

    d = tmp_path_factory.mktemp("transfer")
    _, scene, path, store = orbit_store(d)
    (d / "store.json").write_text(store.to_json(), encoding="utf-8")
    return d / "store.json", store, scene, path


def _transfer_rows(lines: list[str]) -> list[list[str]]:
    rows = [line.strip("|").split(" | ") for line in lines[3:] if line.startswith("| ")]
    return [[c.strip() for c in r] for r in rows if len(r) == 10]


def test_transfer_at_the_stores_own_size_reproduces_its_figures(small_store) -> None:
    """At a pricing camera and the store's own size (priced whole) every stored point renders to its stored
    error and frame time; the verdict column follows the measured figures."""
    store_file, store, scene, path = small_store
    eyes = np.asarray(store.frontier_eyes)
    frame = next(i for i, f in enumerate(path.frames)
                 if np.min(np.linalg.norm(eyes - np.asarray(f.matrix_world)[:3, 3], axis=1)) < 1e-4)
    m = np.asarray(path.frames[frame].matrix_world)
    corner, view = store.locate(m[:3, 3], matrix=m, fov=path.frames[frame].vfov)
    fr = store.frontier(corner, view)
    lines = bss.transfer(store_file, scene, path, [frame], (96, 72), 30.0, 0.02, 1, 1.0, 1e9)
    rows = _transfer_rows(lines)
    assert len(rows) == len(fr.packed) >= 2
    for r in rows:
        stored_e, e, stored_fps, fps, ratio = (float(r[k]) for k in (2, 3, 4, 5, 6))
        assert e == pytest.approx(stored_e, abs=2e-4)
        assert fps == pytest.approx(stored_fps, rel=2e-3) and ratio == pytest.approx(1.0, abs=0.01)
        assert r[9] == ("yes" if e <= 0.02 and fps >= 30.0 else "no")
    summary = lines[-1].strip("|").split(" | ")
    assert int(summary[2]) == len(rows) and int(summary[3]) == sum(r[9] == "yes" for r in rows)
    # the caps choose the candidates from the stored figures alone
    few = _transfer_rows(bss.transfer(store_file, scene, path, [frame], (96, 72), 30.0, 0.02, 1,
                                      float(np.median(fr.error)), 1e9))
    assert len(few) == int(np.sum(fr.error <= np.float32(np.median(fr.error))))


def test_transfer_to_four_times_the_pixels_scales_frame_time(small_store) -> None:
    store_file, _, scene, path = small_store
    rows = _transfer_rows(bss.transfer(store_file, scene, path, [3], (192, 144), 30.0, 0.02, 1, 1.0, 1e9))
    assert rows
    assert all(2.5 < float(r[6]) < 5.0 for r in rows)  # per-pixel work dominates a frame's time
