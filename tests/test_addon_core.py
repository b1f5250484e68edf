"""Pure logic of the add-on (no bpy): path maths, REST client edges, playback logic, report data."""

from __future__ import annotations

import math
import socket
import sys

import numpy as np
import pytest

from addon.core import client as client_mod
from addon.core.job_runner import JobRequest, describe, follow_job
from addon.core.local_service import free_port, serve_command
from addon.core.path_sampling import build_path, frame_times
from addon.core.playback_logic import (
    FRAME_FLAGS,
    PlaybackDriver,
    StoreCache,
    frame_flags,
    missed_rate_text,
    predicted_path_summary,
    summary_text,
    validate_budget,
)
from addon.core.report import (
    FrameRow,
    plot_over_time,
    preset_indices,
    read_csv,
    summarise,
    table3_markdown,
    write_csv,
    write_report,
)
from service.store.camera import camera_lens_from_viewport, vertical_fov
from service.store.temporal import blend
from tests.addon_support import synthetic_store


def test_core_imports_without_bpy() -> None:
    import ast
    from pathlib import Path

    core = Path(__file__).resolve().parent.parent / "addon" / "core"
    for f in core.glob("*.py"):
        tree = ast.parse(f.read_text())
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in {"bpy", "mathutils", "blf", "gpu"} for n in names), f


# -- path maths -------------------------------------------------------------------------------------------
def _angles(lens: float = 50.0, sensor_w: float = 36.0, sensor_h: float = 24.0) -> tuple[float, float]:
    return 2 * math.atan(sensor_w / (2 * lens)), 2 * math.atan(sensor_h / (2 * lens))


def test_vertical_fov_matches_sensor_geometry() -> None:
    # 50 mm on a 36 mm sensor, 16:9: horizontal fov from the width, vertical from the aspect
    h, v_sensor = _angles()
    v = vertical_fov(h, v_sensor, "AUTO", 1920, 1080)
    assert v == pytest.approx(2 * math.atan(18 / 50 * 1080 / 1920))
    # portrait with AUTO: the sensor width fits the larger (vertical) side
    assert vertical_fov(h, v_sensor, "AUTO", 1080, 1920) == pytest.approx(h)
    assert vertical_fov(h, v_sensor, "VERTICAL", 1920, 1080) == pytest.approx(2 * math.atan(12 / 50))
    assert vertical_fov(h, v_sensor, "HORIZONTAL", 1080, 1920) == pytest.approx(
        2 * math.atan(math.tan(h / 2) * 1920 / 1080))
    # non-square pixels widen the displayed image
    square = vertical_fov(h, v_sensor, "AUTO", 1000, 1000)
    assert vertical_fov(h, v_sensor, "AUTO", 1000, 1000, 2.0, 1.0) < square


@pytest.mark.parametrize("bad", [dict(angle_x=0.0), dict(angle_x=math.nan), dict(angle_y=math.pi),
                                 dict(width=0), dict(sensor_fit="X")])
def test_vertical_fov_rejects_bad_input(bad: dict) -> None:
    h, v = _angles()
    args = dict(angle_x=h, angle_y=v, sensor_fit="AUTO", width=64, height=48)
    args.update(bad)
    with pytest.raises(ValueError):
        vertical_fov(**args)


def test_viewport_lens_and_frame_times() -> None:
    assert camera_lens_from_viewport(50, 36) == pytest.approx(25)
    assert frame_times(1, 4, 2.0) == [(1, 0.0), (2, 0.5), (3, 1.0), (4, 1.5)]
    assert frame_times(1, 5, 1.0, step=2) == [(1, 0.0), (3, 2.0), (5, 4.0)]
    with pytest.raises(ValueError):
        frame_times(5, 1, 24)


def test_build_path_round_trips_through_the_shared_format() -> None:
    m = np.eye(4)
    m[:3, 3] = (1, 2, 3)
    path = build_path([(0.0, m, 0.7, (64, 48)), (0.5, m, 0.8, (64, 48))], 2.0)
    doc = path.to_dict()
    assert doc["version"] == 1 and doc["fps"] == 2.0 and len(doc["frames"]) == 2
    assert doc["frames"][1]["matrix_world"][1][3] == 2
    with pytest.raises(ValueError):
        build_path([(0.0, np.full((4, 4), np.nan), 0.7, (64, 48))], 24)
    with pytest.raises(ValueError):
        build_path([], 24)


# -- client edges -----------------------------------------------------------------------------------------
def test_client_validates_urls() -> None:
    assert client_mod.normalise_base_url("http://127.0.0.1:8765/") == "http://127.0.0.1:8765"
    for bad in ("ftp://x", "127.0.0.1:80", "http://", "http://h/?q=1"):
        with pytest.raises(ValueError):
            client_mod.ServiceClient(bad)
    assert client_mod.is_loopback("http://localhost:1") and not client_mod.is_loopback("http://10.0.0.2:1")


def test_client_reports_a_service_that_is_down() -> None:
    port = free_port()
    c = client_mod.ServiceClient(f"http://127.0.0.1:{port}", timeout_s=2)
    with pytest.raises(client_mod.ServiceUnavailable, match="no render-budget service"):
        c.health()


def test_client_reports_http_errors_with_the_service_message() -> None:
    """A real socket server answering one request with the service's error shape."""
    import threading

    body = b'{"error": {"status": 404, "code": "not_found", "message": "job \'x\' not found"}}'
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)

    def serve() -> None:
        conn, _ = srv.accept()
        conn.recv(65536)
        conn.sendall(b"HTTP/1.1 404 Not Found\r\nContent-Type: application/json\r\nContent-Length: "
                     + str(len(body)).encode() + b"\r\nConnection: close\r\n\r\n" + body)
        conn.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    c = client_mod.ServiceClient(f"http://127.0.0.1:{srv.getsockname()[1]}", timeout_s=5)
    with pytest.raises(client_mod.ServiceError) as info:
        c.job("x")
    t.join(5)
    srv.close()
    assert info.value.status == 404 and "not found" in info.value.message


def test_upload_refuses_what_is_not_a_scene(tmp_path) -> None:
    f = tmp_path / "x.glb"
    f.write_bytes(b"not a glb")
    with pytest.raises(ValueError, match="neither a render-budget scene file nor a binary glTF"):
        client_mod.ServiceClient("http://127.0.0.1:9").upload_scene(f)


def test_job_request_validates_and_sends_only_overrides() -> None:
    o = JobRequest(profile="mobile", parameters=("max_depth",),
                   options={"max_depth": 1, "eval_width": 32, "eval_height": 24, "guard_frames": 2})
    body = o.payload("a" * 64, {"version": 1, "fps": 24.0, "frames": []})
    assert body["parameters"] == ["max_depth"]
    # guard_frames is at its default: not sent
    assert body["options"] == {"max_depth": 1, "eval_width": 32, "eval_height": 24}
    assert o.option("population") == 24 and o.option("max_depth") == 1
    # the payload is what the service's schema accepts, field for field
    from service.api.schemas import JobOptionsIn

    assert JobOptionsIn(**body["options"]).model_dump(exclude_unset=True) == body["options"]
    for bad in ({"threshold_power_w": 0}, {"threshold_error": 2}, {"max_depth": 9}, {"eval_height": 2},
                {"view_sampling": "random"}, {"path_resolution": 0.0}, {"guard_frames": 9},
                {"min_depth": 3, "max_depth": 2}, {"no_such_option": 1}):
        with pytest.raises(ValueError):
            JobRequest(options=bad)
    with pytest.raises(ValueError):
        JobRequest(parameters=())
    assert JobRequest(space={"ao_samples": [0, 10]}).payload("a" * 64, {})["space"] == {"ao_samples": [0, 10]}
    with pytest.raises(ValueError, match="not a value"):
        JobRequest(space={"ao_samples": [3]})


def test_describe_job_progress() -> None:
    u = describe({"state": "running", "progress": {"views_done": 3, "views_planned": 12, "evaluations": 40}})
    assert u.fraction == pytest.approx(0.25) and "3/12 views" in u.text
    assert describe({"state": "done", "progress": {}}).fraction == 1.0
    # inside a level: views finish together, the renders show the progress
    mid = {"state": "running", "progress": {"views_done": 0, "views_planned": 48, "evaluations": 576,
                                            "phase": "level 0"}}
    assert describe(mid).fraction == 0.0
    u = describe(mid, evals_per_view=24)
    assert u.fraction == pytest.approx(0.5) and "[level 0]" in u.text


def test_describe_follows_the_services_fraction_through_the_display_pricing() -> None:
    """While the display pricing runs every view is done: the views' count reads 100 %, the service's
    whole-job fraction does not, and describe() shows the latter (older services: the views' count)."""
    pricing = {"views_done": 9, "views_planned": 9, "evaluations": 180, "cache_hits": 4, "estimate_s": 470.0,
               "phase": "price at display resolution"}
    old = {"state": "running", "progress": pricing}
    assert describe(old).fraction == 1.0 and describe(old, evals_per_view=18).fraction == 1.0
    new = {"state": "running", "progress": {**pricing, "fraction": 0.2164}}
    for u in (describe(new), describe(new, evals_per_view=18)):
        assert u.fraction == pytest.approx(0.2164)
        assert u.text == ("running [price at display resolution]: 22 %, 9/9 views, 180 evaluations "
                          "(4 cached), ~470 s left")
    # with the time spent (every service since the job's elapsed time was summed over its attempts)
    timed = {"state": "running", "progress": {**pricing, "fraction": 0.2164, "elapsed_s": 1234.6}}
    assert describe(timed).text == ("running [price at display resolution]: 22 %, 9/9 views, 180 "
                                    "evaluations (4 cached), 1235 s in, ~470 s left")
    for bad in (None, float("nan"), True, "12"):
        assert " s in" not in describe({"state": "running", "progress": {**pricing, "elapsed_s": bad}}).text
    assert describe({"state": "running", "progress": {**pricing, "fraction": None}}).fraction == 1.0
    done = describe({"state": "done", "progress": {**pricing, "fraction": 1.0, "phase": "done"}})
    assert done.fraction == 1.0 and done.text == "done: 9/9 views, 180 evaluations (4 cached)"


class _ScriptedJobs:
    """A service's GET /jobs/{id} answers in turn (the last one repeated) and the cancels it was asked."""

    def __init__(self, bodies) -> None:
        self.bodies, self.cancels = iter(bodies), []
        self.last: dict = {}

    def job(self, job_id: str) -> dict:
        self.last = next(self.bodies, self.last)
        return self.last

    def cancel_job(self, job_id: str) -> dict:
        self.cancels.append(job_id)
        self.bodies, self.last = iter(()), {**self.last, "state": "cancelled"}
        return self.last


def _running(fraction: float, elapsed_s: float) -> dict:
    return {"id": "j", "state": "running", "progress": {
        "views_done": 9, "views_planned": 9, "evaluations": 180, "phase": "price at display resolution",
        "fraction": fraction, "elapsed_s": elapsed_s, "estimate_s": 600.0 - elapsed_s}}


class _Clock:
    """``time`` for the job runner: sleeping moves the clock, nothing else does."""

    def __init__(self) -> None:
        self.now = 0.0

    def monotonic(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


def test_a_job_is_given_up_when_it_stops_progressing_not_when_it_takes_long(monkeypatch) -> None:
    """Command-line clients give a job up when its progress stands still for ``stall_s`` (its clock
    fields alone moving), not after a total time: a heavy scene's healthy job runs for hours (a one-hour
    limit stopped the lab's 320x180 main job in its bridging). A queued job is not stalled: it waits its
    turn. The job given up is cancelled on the service first."""
    from addon.core import job_runner

    monkeypatch.setattr(job_runner, "time", _Clock())
    stall_s, poll_s = 0.25, 0.01
    # moving for 0.8 s of polling, three times the stall limit, then done
    done = {"id": "j", "state": "done", "progress": {}}
    moving = [_running(i / 1000, float(i)) for i in range(80)] + [done]
    jobs = _ScriptedJobs(moving)
    assert follow_job(jobs, moving[0], poll_s=poll_s, stall_s=stall_s)["state"] == "done" and not jobs.cancels
    # queued as long, then running and done
    queued = [{"id": "j", "state": "queued", "progress": {}}] * 80 + moving[:3] + moving[-1:]
    jobs = _ScriptedJobs(queued)
    assert follow_job(jobs, queued[0], poll_s=poll_s, stall_s=stall_s)["state"] == "done" and not jobs.cancels
    # stuck at one camera: only the elapsed time and the estimate change
    stuck = [_running(0.5, float(i)) for i in range(10_000)]
    jobs = _ScriptedJobs(stuck)
    with pytest.raises(TimeoutError, match=r"made no progress for 0\.25 s"):
        follow_job(jobs, stuck[0], poll_s=poll_s, stall_s=stall_s)
    assert jobs.cancels == ["j"]
    # a total limit still applies when one is given
    jobs = _ScriptedJobs(moving)
    with pytest.raises(TimeoutError, match=r"did not finish within 0\.1 s"):
        follow_job(jobs, moving[0], poll_s=poll_s, timeout_s=0.1, stall_s=stall_s)
    assert jobs.cancels == ["j"]


def test_serve_command(tmp_path) -> None:
    cmd = serve_command(sys.executable, 8123, tmp_path, token="t")
    assert cmd[-9:] == ["serve", "--host", "127.0.0.1", "--port", "8123", "--data-dir", str(tmp_path),
                        "--token", "t"]
    with pytest.raises(FileNotFoundError):
        serve_command(tmp_path / "nope", 8123, tmp_path)


# -- playback logic --------------------------------------------------------------------------------------
def _look(direction: tuple[float, float, float], pos=(0.0, 0.0, 0.0)) -> np.ndarray:
    f = np.asarray(direction, dtype=float)
    f /= np.linalg.norm(f)
    up = np.array([0.0, 0.0, 1.0]) if abs(f[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = r, u, -f, pos
    return m


@pytest.mark.parametrize(("mode", "value"), [("POWER", 0.0), ("POWER", -1), ("ERROR", 1.5),
                                             ("ERROR", math.nan), ("WATTS", 1.0), ("POWER", math.inf)])
def test_invalid_budgets_are_rejected(mode: str, value: float) -> None:
    with pytest.raises(ValueError):
        validate_budget(mode, value)


def test_playback_driver_matches_store_lookup_and_filters_changes() -> None:
    store = synthetic_store()
    drv = PlaybackDriver(store, period_s=2.0)
    m_x, m_y = _look((1, 0, 0)), _look((0, 1, 0))
    budget = 0.05  # every point of these frontiers but the cheapest keeps it: room to blend
    first = drv.step(m_x, 0.69, 16 / 9, 0.0, "ERROR", budget)
    ref = store.lookup(m_x[:3, 3], matrix=m_x, fov=0.69, aspect=16 / 9, error_budget=budget)
    assert first.target_indices == ref.indices and first.active_indices == ref.indices
    assert first.predicted_power_w == pytest.approx(ref.power_w)
    # turn to another view: new target, the filter moves along the new frontier over T = 2 s
    hit = store.lookup(m_y[:3, 3], matrix=m_y, fov=0.69, aspect=16 / 9, error_budget=budget)
    target = hit.indices
    assert target != ref.indices
    allowed = {p.indices: p for p in store.budget_points(hit)}
    seen = [drv.step(m_y, 0.69, 16 / 9, t, "ERROR", budget) for t in (0.1, 1.0, 1.9, 2.1, 3.0)]
    # just after the change: the allowed point whose predicted error is nearest the old settings' (their
    # error on the new frontier when they are on it, else the one they were shown at)
    errors = {k: p.error for k, p in allowed.items()}
    start = errors.get(ref.indices, first.predicted_error)
    assert seen[0].active_indices == blend(ref.indices, target, 0.0, errors, start)
    for s in seen:
        assert s.target_indices == target
        assert s.active_indices in allowed  # a point of the new frontier within the budget ...
        assert s.predicted_error == allowed[s.active_indices].error <= budget  # ... and its prediction
    assert seen[-2].active_indices == target and not seen[-1].in_transition


def test_budget_change_takes_effect_through_the_filter() -> None:
    store = synthetic_store()
    drv = PlaybackDriver(store, period_s=1.0)
    m = _look((0, -1, 0))
    a = drv.step(m, 0.69, 1.5, 0.0, "POWER", 10.0)  # generous: maximum quality
    b = drv.step(m, 0.69, 1.5, 0.5, "POWER", 1.7)  # tight: cheapest points
    assert a.target_indices[0] == 0 and a.predicted_error == 0.0  # quality level 0: maximum
    assert b.target_indices != a.target_indices and b.predicted_power_w <= 1.7
    # only the cheapest point keeps 1.7 W: the filter goes there at once rather than break the budget
    assert not b.in_transition
    c = drv.step(m, 0.69, 1.5, 1.6, "POWER", 1.7)
    assert c.active_indices == c.target_indices == b.target_indices
    assert drv.step(m, 0.69, 1.5, 1.7, "POWER", 0.01).infeasible  # below the frontier: nearest, flagged


def test_store_cache_parses_once_per_key() -> None:
    text = synthetic_store().to_json()
    cache = StoreCache()
    calls = []

    def load() -> str:
        calls.append(1)
        return text

    d1 = cache.driver(("t", 1), load, 2.0)
    assert cache.driver(("t", 1), load, 2.0) is d1 and len(calls) == 1
    assert cache.driver(("t", 2), load, 2.0) is not d1 and len(calls) == 2
    with pytest.raises(ValueError):
        cache.driver(("t", 3), lambda: '{"format": "nope"}', 2.0)


def test_predicted_summary_reports_savings() -> None:
    from service.camera_path import CameraFrame

    store = synthetic_store()
    frames = [CameraFrame(i / 24, _look((math.cos(i / 5), math.sin(i / 5), 0), (i * 0.1, 0, 0)), 0.69,
                          (64, 36)) for i in range(30)]
    s = predicted_path_summary(store, frames, "ERROR", 0.01)
    assert s["views"] == 48 and s["corners"] == 8 and s["frames"] == 30
    assert 0.0 < s["predicted_saving"] < 1.0
    assert s["mean_power_w"] < s["mean_max_quality_power_w"]
    assert predicted_path_summary(store, frames, "ERROR", 0.0)["predicted_saving"] == pytest.approx(0.0)
    assert s["mean_fps"] is None and "frame rate unknown" in summary_text(s)


def test_playback_and_summary_carry_the_frame_rate() -> None:
    """With frame times (format 4) the playback frame and the panel's summary say the frame rate the
    store's choice reaches; the max-quality setting, too slow for 24 fps, is never chosen."""
    from service.camera_path import CameraFrame

    store = synthetic_store(timed=True)
    m = _look((1.0, 0.2, 0.1), (0.0, 0.0, 0.0))
    pf = PlaybackDriver(store, 0.0).step(m, 0.69, 16 / 9, 0.0, "ERROR", 0.0)
    assert pf.meets_fps is True and pf.predicted_fps == 24.0
    assert pf.infeasible and pf.predicted_error > 0.0  # error 0 only at max quality, which cannot keep up
    frames = [CameraFrame(i / 24, _look((math.cos(i / 5), math.sin(i / 5), 0), (i * 0.1, 0, 0)), 0.69,
                          (64, 36)) for i in range(10)]
    s = predicted_path_summary(store, frames, "POWER", 3.0)
    assert s["mean_fps"] == 24.0 and s["slow_frames"] == 0 and s["fps_target"] == 24.0
    assert summary_text(s).endswith("24.0 of 24 fps; figures of a size the store does not record")


def test_the_summary_says_which_display_its_figures_hold_for() -> None:
    """The panel's (and batch's) summary names the display the store's figures were priced for, and
    the scene's render size when it is another; preview figures are called so, never a display's."""
    from dataclasses import replace

    from service.camera_path import CameraFrame

    frames = [CameraFrame(i / 24, _look((math.cos(i / 5), math.sin(i / 5), 0), (i * 0.1, 0, 0)), 0.69,
                          (1280, 720)) for i in range(6)]
    store = synthetic_store(timed=True)
    display = replace(store, meta={**store.meta, "figures_resolution": [640, 360],
                                   "display_pricing": "tiles:ssim"})
    text = summary_text(predicted_path_summary(display, frames, "POWER", 3.0))
    assert text.endswith("24.0 of 24 fps; figures for a 640x360 display, not this scene's 1280x720")
    same = [replace(f, resolution=(640, 360)) for f in frames]
    assert summary_text(predicted_path_summary(display, same, "POWER", 3.0)).endswith(
        "figures for a 640x360 display")
    preview = replace(store, meta={**store.meta, "figures_resolution": [64, 36],
                                   "display_pricing": "preview"})
    text = summary_text(predicted_path_summary(preview, frames, "POWER", 3.0))
    assert text.endswith("figures from 64x36 preview renders, power scaled by the pixel count")
    assert "display" not in text.split("; ")[-1]


def test_a_missed_frame_rate_is_worded_once_per_priority() -> None:
    """The one wording the HUD, the panel and the render engine's frame notes use: the target, and under
    budget first that the budget is why; an unknown target (0 or None) is "the frame rate"."""
    assert missed_rate_text(24.0, "frame_rate") == "no setting keeps up with 24 fps here"
    assert missed_rate_text(12.5, "budget") == ("budget first: misses 12.5 fps here (nothing within the "
                                                "budget keeps up)")
    assert missed_rate_text(0.0, "frame_rate") == missed_rate_text(None, "frame_rate") == (
        "no setting keeps up with the frame rate here")


def test_a_frames_flags_are_worded_once_with_the_huds_short_forms_in_the_same_place() -> None:
    """Every per-frame flag the HUD, the panels and the render engine's frame notes show comes from
    ``frame_flags``, most serious first: the long forms (panels, notes) from :data:`FRAME_FLAGS` and
    ``missed_rate_text``, the HUD's short forms the start of the same words; artist's words, not the
    store's internals."""
    every = dict.fromkeys(("infeasible", "slow", "clamped", "in_transition"), True)
    assert frame_flags(**every, fps_target=24.0, priority="budget") == [
        FRAME_FLAGS["infeasible"][1], missed_rate_text(24.0, "budget"), FRAME_FLAGS["clamped"][1],
        FRAME_FLAGS["in_transition"][1]]
    assert frame_flags(**every, fps_target=24.0, short=True) == [
        FRAME_FLAGS["infeasible"][0], missed_rate_text(24.0, "frame_rate"), FRAME_FLAGS["clamped"][0],
        FRAME_FLAGS["in_transition"][0]]
    assert frame_flags(clamped=True, short=True) == ["camera outside the optimised area"]
    assert frame_flags(infeasible=True) == ["budget cannot be met here: the setting closest to it is used"]
    assert frame_flags() == frame_flags(fps_target=24.0, short=True) == []
    for short, long in FRAME_FLAGS.values():
        assert long.startswith(short) and len(short) <= 40, (short, long)  # one wording, short enough
        assert not any(word in long for word in ("store", "infeasible", "clamp", "Eq.")), long


# -- report data ------------------------------------------------------------------------------------------
def test_preset_indices_follow_each_parameters_quality_end() -> None:
    counts, mq = [4, 3, 2, 1], [0, 2, 0, 0]
    assert preset_indices(counts, mq, 1.0) == [0, 2, 0, 0]
    assert preset_indices(counts, mq, 0.0) == [3, 0, 1, 0]
    assert preset_indices(counts, mq, 0.5) == [2, 1, 1, 0]  # halfway rounds up the index
    with pytest.raises(ValueError):
        preset_indices([2], [2], 0.5)


def _rows() -> list[FrameRow]:
    rows = []
    for f in range(10):
        t = f / 10
        rows += [FrameRow(f, t, "max", 4.0, 0.0), FrameRow(f, t, "min", 1.0, 0.2),
                 FrameRow(f, t, "ours", 2.0 + (f % 2), 0.01, budget_kept=f % 2 == 0)]
    return rows


def test_table3_layout_and_savings() -> None:
    s = {x.mode: x for x in summarise(_rows())}
    assert s["ours"].mean_power_w == pytest.approx(2.5) and s["ours"].saving_vs_max == pytest.approx(0.375)
    assert s["ours"].budget_kept_fraction == pytest.approx(0.5) and s["max"].budget_kept_fraction is None
    md = table3_markdown(summarise(_rows()))
    lines = md.splitlines()
    assert lines[0].split("|")[2:5] == [" Ours ", " Max ", " Min "]
    assert lines[2].startswith("| Avg. Power (W) | 2.500 | 4.000 | 1.000")
    assert lines[3].startswith("| Avg. Error (e) | 0.0100 | 0.0000 | 0.2000")
    with pytest.raises(ValueError):
        FrameRow(0, 0.0, "max", math.nan, 0.0)


def test_csv_round_trip_and_report_folder(tmp_path) -> None:
    rows = _rows()
    assert read_csv(write_csv(tmp_path / "a.csv", rows)) == rows
    written = write_report(tmp_path / "rep", rows, title="t", budget=("POWER", 2.5))
    assert (tmp_path / "rep" / "report.md").read_text().count("Avg. Power") == 1
    assert (tmp_path / "rep" / "power_over_time.png").stat().st_size > 1000
    assert "plots_skipped" not in written
    assert len(plot_over_time(rows, tmp_path / "p")) == 2


def test_memoised_lookups_equal_fresh_ones() -> None:
    store = synthetic_store()
    mats = [_look((math.cos(a), math.sin(a), 0.2), (a, -a, 1.0)) for a in np.linspace(0, 6, 40)]
    drv = PlaybackDriver(store, period_s=0.0)
    first = [drv.step(m, 0.69, 1.7, i / 24, "ERROR", 0.01) for i, m in enumerate(mats)]
    assert drv.memo_hits == 0
    again = [drv.step(m, 0.69, 1.7, (40 + i) / 24, "ERROR", 0.01) for i, m in enumerate(mats)]
    assert drv.memo_hits == len(mats)
    for a, b, m in zip(first, again, mats, strict=True):
        ref = store.lookup(m[:3, 3], matrix=m, fov=0.69, aspect=1.7, error_budget=0.01)
        assert a.target_indices == b.target_indices == ref.indices
        assert b.predicted_power_w == ref.power_w and b.infeasible == ref.infeasible
    # a different budget is a different key
    drv.step(mats[0], 0.69, 1.7, 5.0, "ERROR", 0.02)
    assert drv.memo_hits == len(mats)


def test_predictions_round_trip_and_are_compared_in_the_report(tmp_path) -> None:
    from addon.core.report import prediction_notes

    rows = [*_rows(), FrameRow(11, 1.1, "ours", 2.0, 0.05, "", False, 1.8, 0.02)]
    assert read_csv(write_csv(tmp_path / "p.csv", rows)) == rows
    notes = prediction_notes(rows)
    assert len(notes) == 1 and "predicted mean error 0.0200" in notes[0] and "0.0500" in notes[0]
    assert "frame rate" not in notes[0]  # a store before frame times predicts none
    timed = [FrameRow(12, 1.2, "ours", 0.5, 0.01, "", True, 0.5, 0.01, 30.0, True, 30.0),
             FrameRow(13, 1.3, "ours", 0.7, 0.01, "", True, 0.6, 0.01, 20.0, False, 30.0)]
    assert read_csv(write_csv(tmp_path / "t.csv", timed)) == timed
    (note,) = prediction_notes(timed)
    assert note.endswith("frame rate predicted 30 fps, reached 25 fps (equal on 1 of 2)")
    assert "(2 frames; power within 10 % on 1, mean |error predicted - measured| 0.0000)" in note
    text = (write_report(tmp_path / "r", rows, title="t", budget=("ERROR", 0.02), plot=False)["report"]
            ).read_text()
    assert "store predicted" in text
