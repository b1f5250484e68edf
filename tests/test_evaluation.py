"""Evaluation on the real tracer: error against the max-quality reference, power, cache, executors,
exhaustive enumeration against brute force, NSGA-II against the exact frontier."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from sim_core.image import linear_to_srgb, upsample_bilinear
from tracer_scenes import teapot_scene

import sim_core
from service import evaluation, nsga
from service.eval_cache import EvalCache
from service.evaluation import CameraSpec, Evaluator, SceneHandle, evaluate
from service.executors import DaskExecutor, InProcessExecutor, ProcessPoolExecutor
from service.lru import LRUCache
from service.params import default_space


@pytest.fixture(scope="module")
def scene() -> sim_core.Scene:
    return teapot_scene()


def _cam(w: int = 32, h: int = 24) -> CameraSpec:
    return CameraSpec((0.0, -9.0, 5.0), (0.0, 9.0, -4.0), (0.0, 0.0, 1.0), 0.7, w, h)


SMALL = ("max_depth", "shadow_samples", "resolution_scale")  # 64 settings


def test_display_transform_and_upsample() -> None:
    x = np.array([-1.0, 0.0, 0.0031308, 0.5, 1.0, 7.0])
    y = linear_to_srgb(x)
    assert y[0] == 0.0 and y[-1] == pytest.approx(1.0) and y[-2] == pytest.approx(1.0)
    assert np.all(np.diff(y[1:]) >= 0) and y[3] == pytest.approx(0.7353569, abs=1e-6)
    img = np.arange(12, dtype=float).reshape(3, 4)
    assert np.array_equal(upsample_bilinear(img, 3, 4), img)
    up = upsample_bilinear(np.dstack([img] * 3), 6, 8)
    assert up.shape == (6, 8, 3) and up.min() >= img.min() and up.max() <= img.max()
    assert upsample_bilinear(np.ones((2, 2)), 5, 7) == pytest.approx(np.ones((5, 7)))


def test_error_and_power(scene) -> None:
    sp = default_space()
    mq = sp.max_quality_indices()
    best = evaluate(scene, _cam(), mq, sp)
    cheap = evaluate(scene, _cam(), tuple(0 for _ in mq), sp)
    assert best.error == 0.0 and 0.05 < cheap.error <= 1.0
    assert cheap.power_w < best.power_w and cheap.frame_time_s < best.frame_time_s
    assert best.breakdown["energy_j.static"] > 0
    # power extrapolated to a bigger frame: static power stays, dynamic energy and frame time grow with
    # the pixels, and the power is drawn at the frame rate the bigger frame reaches
    static_w = sim_core.load_profile("mobile").static_power_w
    assert best.frame_time_s <= 1 / 30 and best.breakdown["fps"] == 30.0  # the small frame keeps up
    assert best.breakdown["energy_j.static"] == pytest.approx(static_w / 30.0)
    dynamic = (best.power_w - static_w) / 30.0  # energy of one frame at the rendered size
    for ratio in (100, 10_000):
        big = evaluate(scene, _cam(), mq, sp, target_pixels=32 * 24 * ratio)
        assert big.frame_time_s == pytest.approx(ratio * best.frame_time_s, rel=1e-12)
        rate = min(30.0, 1.0 / big.frame_time_s)
        assert big.breakdown["fps"] == pytest.approx(rate, rel=1e-12)
        assert big.power_w == pytest.approx(static_w + ratio * dynamic * rate, rel=1e-9)
        # never above the full-speed power, which the pixel ratio does not change (E and t scale alike)
        assert big.power_w <= static_w + dynamic / best.frame_time_s * (1 + 1e-12)
    assert big.frame_time_s > 1 / 30 and big.power_w == pytest.approx(static_w + dynamic / best.frame_time_s)
    # lower resolution scale renders a smaller image, upsampled before SSIM: error but finite
    idx = list(mq)
    idx[sp.names.index("resolution_scale")] = 0
    low = evaluate(scene, _cam(), idx, sp)
    assert 0.0 < low.error < 1.0 and low.power_w < best.power_w
    with pytest.raises(ValueError):
        evaluate(scene, _cam(), mq, sp, metric="nope")
    with pytest.raises(ValueError):
        evaluate(scene, _cam(), (99,) * 8, sp)


class _CountingRender:
    """``service.evaluation._render`` that counts renders by settings and can hold chosen ones at a
    barrier (the renders that must be in flight together)."""

    def __init__(self, real, hold=(), barrier=None) -> None:
        self.real, self.hold, self.barrier = real, hold, barrier
        self.calls: list[object] = []
        self.lock = threading.Lock()

    def __call__(self, scene, camera, settings, threads):
        with self.lock:
            self.calls.append(settings)
        if settings in self.hold:
            self.barrier.wait()
        return self.real(scene, camera, settings, threads)


def test_max_quality_is_priced_from_its_reference_render(scene, monkeypatch) -> None:
    """Evaluating maximum quality costs no render beyond the camera's reference, and gives exactly what
    pricing a render of its own gives (the tracer is deterministic)."""
    sp = default_space()
    mq = sp.max_quality_indices()
    cam = _cam(24, 16)
    evaluation._REFS.clear()
    counting = _CountingRender(evaluation._render)
    monkeypatch.setattr(evaluation, "_render", counting)
    best = evaluate(scene, cam, mq, sp, target_pixels=320 * 180)
    assert counting.calls == [sp.to_settings(mq)]  # the reference, once
    again = evaluate(scene, cam, mq, sp, target_pixels=320 * 180)
    assert len(counting.calls) == 1 and again == best
    fresh = sim_core.render(scene, cam.to_camera(), sp.to_settings(mq))
    power, frame_time, breakdown = evaluation._price(fresh, "mobile", 30.0, 320 * 180 / (24 * 16))
    assert (best.error, best.power_w, best.frame_time_s) == (0.0, power, frame_time)
    assert best.breakdown == breakdown


def test_concurrent_evaluations_at_one_camera_render_its_reference_once(scene, monkeypatch) -> None:
    """Two evaluations at one camera in two threads: both renders of their settings are in flight at
    once (the tracer releases the GIL; a barrier holds each until the other has started), and the
    reference both need is rendered once."""
    sp = default_space()
    mq = sp.max_quality_indices()
    cam = _cam(24, 16)
    a = tuple(0 for _ in mq)
    b = tuple(v // 2 for v in mq)
    evaluation._REFS.clear()
    counting = _CountingRender(evaluation._render, hold=(sp.to_settings(a), sp.to_settings(b)),
                               barrier=threading.Barrier(2, timeout=30))
    monkeypatch.setattr(evaluation, "_render", counting)
    with ThreadPoolExecutor(2) as pool:
        got = list(pool.map(lambda x: evaluate(scene, cam, x, sp), (a, b)))
    assert sorted(map(repr, counting.calls)) == sorted(map(repr, [sp.to_settings(x) for x in (mq, a, b)]))
    counting.hold = ()
    serial = [evaluate(scene, cam, x, sp) for x in (a, b)]  # the reference from the cache now
    assert got == serial and len(counting.calls) == 5


def test_cache_answers_repeats_and_persists(scene, tmp_path) -> None:
    sp = default_space().subset(SMALL)
    reqs = [(_cam(), sp.expand(x)) for x in nsga.enumerate_space(sp.free_n_values)[:10]]
    with EvalCache(tmp_path / "c.sqlite") as cache:
        ev = Evaluator(scene, sp, cache=cache)
        first = ev.evaluate(reqs + reqs[:3])
        assert ev.evaluations == 10
        again = ev.evaluate(reqs)
        assert ev.evaluations == 10 and again == first[:10]
    with EvalCache(tmp_path / "c.sqlite") as cache:
        ev2 = Evaluator(scene, sp, cache=cache)
        assert ev2.evaluate(reqs) == first[:10] and ev2.evaluations == 0 and ev2.cache_hits == 10
        # another profile or fps is another key: rendered again
        ev3 = Evaluator(scene, sp, cache=cache, fps=60.0)
        ev3.evaluate(reqs[:2])
        assert ev3.evaluations == 2


def test_an_edited_profile_is_priced_afresh_not_served_from_the_cache(scene, tmp_path, monkeypatch) -> None:
    """The cache keys a profile by its figures too: a profile file edited (or a product upgrade that
    changes a shipped one) under the same name must not get the old figures back from a kept cache."""
    prof = tmp_path / "mine.toml"
    mobile = (Path(sim_core.energy.__file__).with_name("profiles") / "mobile.toml").read_text()
    prof.write_text(mobile.replace('name = "mobile"', 'name = "mine"'))
    sp = default_space().subset(SMALL)
    reqs = [(_cam(), sp.expand(x)) for x in nsga.enumerate_space(sp.free_n_values)[:3]]
    with EvalCache(tmp_path / "c.sqlite") as cache:
        before = Evaluator(scene, sp, cache=cache, profile=str(prof)).evaluate(reqs)
        static = sim_core.load_profile(prof).static_power_w
        prof.write_text(prof.read_text().replace(f"power_w = {static}", f"power_w = {static + 1.0}"))
        monkeypatch.setattr(evaluation, "_PROFILES", {})  # a new process: the profile is read again
        ev = Evaluator(scene, sp, cache=cache, profile=str(prof))
        after = ev.evaluate(reqs)
        assert ev.evaluations == 3 and ev.cache_hits == 0
        for b, a in zip(before, after, strict=True):
            assert a.error == b.error and a.power_w == pytest.approx(b.power_w + 1.0, rel=1e-9)
        # the description is not a figure: still the same key
        prof.write_text(prof.read_text().replace('description = "', 'description = "Edited: '))
        monkeypatch.setattr(evaluation, "_PROFILES", {})
        again = Evaluator(scene, sp, cache=cache, profile=str(prof))
        assert again.evaluate(reqs) == after and again.evaluations == 0


def test_executors_give_identical_results(scene) -> None:
    from distributed import Client, LocalCluster

    sp = default_space().subset(SMALL)
    reqs = [(_cam(24, 16), sp.expand(x)) for x in nsga.enumerate_space(sp.free_n_values)[::5]]
    handle = SceneHandle(loader=teapot_scene)
    want = Evaluator(handle, sp, cache=EvalCache(), executor=InProcessExecutor()).evaluate(reqs)
    with ProcessPoolExecutor(2) as pool:
        assert Evaluator(handle, sp, cache=EvalCache(), executor=pool).evaluate(reqs) == want
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cl, \
            Client(cl) as client:
        got = Evaluator(handle, sp, cache=EvalCache(), executor=DaskExecutor(client=client)).evaluate(reqs)
    assert got == want


def test_exhaustive_equals_brute_force(scene) -> None:
    sp = default_space().subset(SMALL)
    cam = _cam()
    ev = Evaluator(scene, sp, cache=EvalCache())

    def f(batch):
        return np.array([(r.error, r.power_w) for r in ev.evaluate([(cam, sp.expand(x)) for x in batch])])

    arch = nsga.optimise(f, sp.free_n_values, exhaustive_limit=512)
    assert len(arch) == sp.size == 64
    # brute force: every setting rendered directly, dominance checked pairwise
    pts = {x: evaluate(scene, cam, sp.expand(x), sp) for x in nsga.enumerate_space(sp.free_n_values)}
    vals = {x: (e.error, e.power_w) for x, e in pts.items()}

    def dominated(a):
        return any(b[0] <= a[0] and b[1] <= a[1] and b != a for b in vals.values())

    exact = {v for v in vals.values() if not dominated(v)}
    assert {(e, p) for _, e, p in arch.frontier()} == exact
    assert len(exact) >= 4


@pytest.mark.slow
def test_nsga_reaches_exact_hypervolume_on_real_space(scene) -> None:
    """>= 5 parameters, 1,280 settings: NSGA-II with <= 30 % of the evaluations reaches >= 0.98 of the
    exact frontier's hypervolume (objectives normalised by the space's extremes)."""
    sp = default_space().subset(("sampling", "max_depth", "shadow_samples", "resolution_scale", "ao_samples"))
    assert sp.size == 1280 and len(sp.free_positions) == 5
    cam = _cam()
    ev = Evaluator(scene, sp, cache=EvalCache(), target_pixels=1920 * 1080)

    def f(batch):
        return np.array([(r.error, r.power_w) for r in ev.evaluate([(cam, sp.expand(x)) for x in batch])])

    xs = nsga.enumerate_space(sp.free_n_values)
    F = f(xs)
    lo, hi = F.min(axis=0), F.max(axis=0)
    hv_exact = nsga.hypervolume_2d((F[nsga.non_dominated_mask(F)] - lo) / (hi - lo), (1.0, 1.0))
    for seed in (0, 1):
        arch = nsga.optimise(f, sp.free_n_values, nsga.NSGAConfig(population=24, generations=16, seed=seed),
                             exhaustive_limit=0)
        assert len(arch) <= 0.3 * sp.size
        fr = np.array([(e, p) for _, e, p in arch.frontier()])
        assert nsga.hypervolume_2d((fr - lo) / (hi - lo), (1.0, 1.0)) >= 0.98 * hv_exact


def test_a_worker_without_the_scene_file_loads_the_shipped_bytes_and_keeps_no_copy(tmp_path,
                                                                                   monkeypatch) -> None:
    """Dask workers without a shared disk get the file's bytes: loaded from a private folder that is gone
    once the scene is in memory; only a self-contained scene can travel that way."""
    import pickle
    import tempfile

    from api_support import box_scene_glb

    from service import evaluation

    system_tmp = tmp_path / "system-tmp"
    system_tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system_tmp))
    glb = tmp_path / "scene.glb"
    glb.write_bytes(box_scene_glb())
    handle = SceneHandle(path=glb, ship_bytes=True)
    travelled = pickle.loads(pickle.dumps(handle))
    glb.unlink()  # the worker's machine has no such file
    monkeypatch.setattr(evaluation, "_SCENES", LRUCache(8))
    travelled._scene = None
    assert str(travelled.get().content_hash) == handle.content_hash
    assert list(system_tmp.iterdir()) == []
    external = b'{"asset": {"version": "2.0"}, "buffers": [{"byteLength": 4, "uri": "x.bin"}]}'
    with pytest.raises(ValueError, match="self-contained"):
        evaluation._load_scene(str(tmp_path / "gone.gltf"), external, False)
    assert list(system_tmp.iterdir()) == []


def test_a_camera_from_a_blender_matrix_is_the_one_the_tracer_builds_from_it(scene) -> None:
    """Path frames, add-on payloads and REST bodies give the camera as Blender's matrix_world; the
    evaluation camera made from it must see what ``Camera.from_blender`` sees."""
    eye, fwd, up = np.array([0.5, -9.0, 5.0]), np.array([0.0, 9.0, -4.0]), np.array([0.0, 0.0, 1.0])
    f = fwd / np.linalg.norm(fwd)
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(right, f), -f, eye
    spec = CameraSpec.from_matrix(m, 0.7, 32, 24)
    assert np.allclose(spec.eye, eye) and np.allclose(spec.forward, f)
    assert np.dot(spec.up, up) > 0.9
    settings = sim_core.RenderSettings()
    ours = sim_core.render(scene, spec.to_camera(), settings).image
    blender = sim_core.render(scene, sim_core.Camera.from_blender(m, 0.7, 32, 24), settings).image
    assert np.allclose(np.asarray(ours), np.asarray(blender), atol=1e-5)
    with pytest.raises(ValueError, match="4x4"):
        CameraSpec.from_matrix(m[:3], 0.7, 32, 24)
