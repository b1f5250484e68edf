"""The main job (`make demo` / `make report`): tools/demo.py end to end against a real local service, on a
tiny configuration, plus the pieces it adds to the shared evaluation code."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import sim_core
from addon.core.report import budget_list

REPO_ROOT = Path(__file__).resolve().parent.parent
TEAPOT = REPO_ROOT / "blend_scenes" / "build" / "teapot"
MODES = {"ours_power", "ours_error", "max", "max_mid", "mid_min", "min"}
TINY = ["--scene", "teapot", "--resolution", "32x18", "--frames", "6", "--max-depth", "0",
        "--population", "4", "--generations", "2", "--samples", "1", "--sample-resolution", "16x9",
        "--display-height", "36", "--display-points", "3", "--verify-frames", "2"]


def _port_closed(url: str) -> bool:
    host, port = url.removeprefix("http://").split(":")
    with socket.socket() as s:
        s.settimeout(1.0)
        return s.connect_ex((host, int(port))) != 0


def test_report_budgets_one_or_several() -> None:
    assert budget_list(("POWER", 2)) == [("POWER", 2.0)]
    assert budget_list([("POWER", 2.0), ("ERROR", 0.02)]) == [("POWER", 2.0), ("ERROR", 0.02)]
    assert budget_list(None) == []


def test_demo_searches_and_measures_on_the_profile_it_is_given() -> None:
    """``--profile`` reaches the optimisation job (the campaign then reads it from the store); a profile
    that is not bundled is refused before anything runs."""
    from tools import demo

    assert demo.job_request(demo.parser().parse_args([])).profile == "mobile"
    assert demo.job_request(demo.parser().parse_args(["--profile", "desktop"])).profile == "desktop"
    finer = demo.job_request(demo.parser().parse_args(
        ["--space", "shadow_samples=0,1,2,4,16", "--space", "ao_samples=0,4,8,10,16"]))
    body = finer.payload("a" * 64, {"version": 1, "fps": 30.0, "frames": []})
    assert body["space"] == {"shadow_samples": [0, 1, 2, 4, 16], "ao_samples": [0, 4, 8, 10, 16]}
    assert "space" not in demo.job_request(demo.parser().parse_args([])).payload("a" * 64, {})
    with pytest.raises(SystemExit):
        demo.parser().parse_args(["--space", "shadow_samples=3"])
    with pytest.raises(SystemExit):
        demo.parser().parse_args(["--profile", "../etc/passwd"])


def test_demo_waits_for_full_size_renders_and_refuses_bad_timeouts() -> None:
    """One request may take minutes at the path's own size on shared cores (a 300 s limit stopped the
    valley's main job at 1280x720), so the local service's client waits --request-timeout; timeouts that
    are not positive finite seconds are refused before anything runs."""
    from tools import demo

    assert demo.parser().parse_args([]).request_timeout == demo.DEMO_REQUEST_TIMEOUT_S >= 1800.0
    assert demo.parser().parse_args(["--request-timeout", "90"]).request_timeout == 90.0
    # the job itself: no limit on its total time (a heavy scene's takes hours), only on a stall
    args = demo.parser().parse_args([])
    assert args.job_timeout is None and args.stall_timeout == demo.JOB_STALL_TIMEOUT_S >= 600.0
    for flag in ("--request-timeout", "--job-timeout", "--stall-timeout"):
        for bad in ("0", "-5", "nan", "inf", "soon"):
            with pytest.raises(SystemExit):
                demo.parser().parse_args([flag, bad])


def test_demo_prices_the_slow_tier_only_when_its_lookups_read_it() -> None:
    """Frame rate first (the default) never picks a setting that misses the rate while one meets it, so
    the demo's store prices max quality alone there (free: the reference render); budget first gets the
    display points; --slow-points wins over both."""
    from tools import demo

    def slow(*argv: str) -> int:
        return demo.job_request(demo.parser().parse_args(list(argv))).options["slow_points"]

    assert slow() == 1 and slow("--priority", "frame_rate") == 1
    assert slow("--priority", "budget") == demo.DEMO_DISPLAY_POINTS
    assert slow("--slow-points", "3") == 3 and slow("--priority", "budget", "--slow-points", "0") == 0
    guards = [demo.job_request(demo.parser().parse_args(argv)).options["guard_frames"]
              for argv in ([], ["--guard-frames", "2"])]
    assert guards == [demo.DEMO_GUARD_FRAMES, 2]
    radii = [demo.job_request(demo.parser().parse_args(argv)).options["guard_radius"]
             for argv in ([], ["--guard-radius", "0.01"])]
    assert radii == [demo.DEMO_GUARD_RADIUS, 0.01] and demo.DEMO_GUARD_RADIUS == 0.05
    bridges = [demo.job_request(demo.parser().parse_args(argv)).options["bridge_points"]
               for argv in ([], ["--bridge-points", "8"])]
    assert bridges == [demo.DEMO_BRIDGE_POINTS, 8] and demo.DEMO_BRIDGE_POINTS == 0


@pytest.mark.slow
@pytest.mark.service
def test_demo_end_to_end_tiny(tmp_path: Path) -> None:
    """The whole main job, its budget modes and verify looked up budget first (--priority) with an error
    margin (--error-margin) and a power margin (--power-margin)."""
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "tools.demo", *TINY, "--priority", "budget",
                           "--error-margin", "0.001", "--power-margin", "0.02", "--out",
                           str(out), "--data-dir", str(tmp_path / "var")], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    url = re.search(r"render-budget serve on (http://\S+),", proc.stdout).group(1)
    assert "service stopped" in proc.stdout and _port_closed(url)
    assert "Avg. Power (W)" in proc.stdout  # the table is printed

    for name in ("report.md", "per_frame.csv", "power_over_time.png", "error_over_time.png", "store.json",
                 "summary.json"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    frames = sorted((out / "frames").iterdir())
    assert {p.suffix for p in frames} == {".png", ".exr"}
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in frames if p.suffix == ".png")
    assert all(p.read_bytes()[:4] == b"\x76\x2f\x31\x01" for p in frames if p.suffix == ".exr")

    summary = json.loads((out / "summary.json").read_text())
    with (out / "per_frame.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert {r["mode"] for r in rows} == MODES
    n = summary["frames_evaluated"]
    assert 1 <= n <= 6 and len(rows) == 6 * n
    power = {m: [float(r["power_w"]) for r in rows if r["mode"] == m] for m in MODES}
    error = {m: [float(r["error"]) for r in rows if r["mode"] == m] for m in MODES}
    assert all(math.isfinite(v) and v > 0 for vs in power.values() for v in vs)
    assert all(math.isfinite(v) and 0.0 <= v <= 1.0 for vs in error.values() for v in vs)
    assert error["max"] == [0.0] * n  # the maximum preset is the reference
    # power is drawn at the frame rate reached (a slow Max may draw less than Max-Mid): energy per frame,
    # not power, orders the presets, and every frame either keeps up with the target or says it did not
    static = sim_core.load_profile(summary["profile"]).static_power_w
    fps = {m: [float(r["fps"]) for r in rows if r["mode"] == m] for m in MODES}
    energy = {m: np.mean([(p - static) / f for p, f in zip(power[m], fps[m], strict=True)]) for m in MODES}
    assert energy["max"] >= energy["max_mid"] >= energy["min"]
    target = summary["fps_target"]
    assert all(0.0 < f <= target for vs in fps.values() for f in vs)
    assert all(r["deadline_met"] == str(int(float(r["fps"]) == target)) for r in rows)
    predicted = [r for r in rows if r["predicted_power_w"]]  # budget-mode frames (every one: frontier points)
    assert len(predicted) == 2 * n
    assert predicted and all(0.0 < float(r["predicted_fps"]) <= target for r in predicted)
    assert np.mean(error["min"]) > 0.0

    # budget-kept flags agree with the measured numbers and the budgets the driver chose
    pb, eb = summary["power_budget_w"], summary["error_budget"]
    for r in rows:
        if r["mode"] == "ours_power":
            assert r["budget_kept"] == str(int(float(r["power_w"]) <= pb))
        elif r["mode"] == "ours_error":
            assert r["budget_kept"] == str(int(float(r["error"]) <= eb))
        else:
            assert r["budget_kept"] == ""
    # the summary's table is the CSV's means
    by_mode = {s["mode"]: s for s in summary["summaries"]}
    for m in MODES:
        assert by_mode[m]["mean_power_w"] == pytest.approx(np.mean(power[m]), rel=1e-4)
        assert by_mode[m]["mean_error"] == pytest.approx(np.mean(error[m]), rel=1e-4, abs=1e-6)
    assert by_mode["max"]["saving_vs_max"] == pytest.approx(0.0, abs=1e-12)

    # the automatic power budget lies within the store's frontiers (between their cheapest and best)
    from service.store import ParetoStore

    store = ParetoStore.from_json((out / "store.json").read_text())
    assert store.stats()["views"] == summary["store"]["views"] and summary["store"]["depth"] == 0
    lo, hi = (float(v) for v in re.findall(r"\(([\d.]+) W\)", summary["budget_choice"]))
    assert lo <= pb <= hi

    report_md = (out / "report.md").read_text()
    for text in ("Avg. Power (W)", "Ours (power budget)", "Ours (error budget)", "Max-Mid", "Budget kept",
                 "Table 2", "Valley (paper)", "Time per phase", "Diagnostic"):
        assert text in report_md, text

    # the store's figures were priced at the stated display size, and verified there
    assert summary["store"]["meta"]["figures_resolution"] == [64, 36]
    # ... and Table 3 measured there too: renders and power at that size, never a preview scaled up
    assert summary["store"]["meta"]["display_pricing"] != "preview"
    assert summary["resolution"] == summary["power_resolution"] == [64, 36]
    assert "Evaluated at 64x36 (the display size the store is priced for" in report_md
    verify = json.loads((out / "verify.json").read_text())
    assert verify["resolution"] == [64, 36] and len(verify["frames"]) == 2
    assert verify["summary"]["within_budget"] == sum(f["measured_error"] <= eb for f in verify["frames"])
    assert "verified at 64x36 (store figures for 64x36)" in (out / "verify.md").read_text()
    assert "within budget:" in proc.stdout
    # --priority and the margins reached both budget modes' lookups and verify's, and the report says it
    assert summary["lookup"] == {"fps": store.fps, "fps_given": None, "priority": "budget",
                                 "error_margin": 0.001, "power_margin": 0.02}
    assert verify["priority"] == "budget" and "budget first" in (out / "verify.md").read_text()
    assert verify["error_margin"] == 0.001 and "0.001 error margin" in (out / "verify.md").read_text()
    assert (f"### Table 3: budget modes looked up for {store.fps:g} fps (the store's own), budget first, "
            "the error budget with a 0.001 margin, the power budget with a 2 % margin" in report_md)
    assert "Power margin 2 %: the power-budget mode chose among the settings predicted to draw at most 98 %" \
        in report_md
    assert "Priority: budget first." in report_md and "budget first)" in proc.stdout


@pytest.mark.slow
@pytest.mark.service
def test_demo_stops_the_service_on_sigterm(tmp_path: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "tools.demo", *TINY, "--generations", "50", "--out",
                             str(tmp_path / "out"), "--data-dir", str(tmp_path / "var")], cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    url = None
    try:
        deadline = time.monotonic() + 120
        for line in proc.stdout:
            m = re.search(r"render-budget serve on (http://\S+),", line)
            url = url or (m.group(1) if m else None)
            if "optimise the path" in line or time.monotonic() > deadline:
                break
        assert url is not None
        time.sleep(1.0)
        os.kill(proc.pid, signal.SIGTERM)
        rest, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert "service stopped" in rest
    assert _port_closed(url)


@pytest.mark.slow
@pytest.mark.service
def test_a_rerun_after_a_hard_kill_follows_the_job_its_service_took_up_again(tmp_path: Path) -> None:
    """The demo and its service killed outright (a crash, a lost session: no cancel reaches the service)
    leave the job running in the data folder, and the next start of the service takes it up again. The
    same command again follows that job instead of submitting a second one that would run beside it."""
    command = [sys.executable, "-m", "tools.demo", *TINY, "--generations", "50", "--out",
               str(tmp_path / "out"), "--data-dir", str(tmp_path / "var")]
    proc = subprocess.Popen(command, cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            text=True, start_new_session=True)
    job_id = None
    log = tmp_path / "var" / "service.log"
    try:
        deadline = time.monotonic() + 120
        for line in proc.stdout:
            m = re.search(r"job (\w+) queued", line)
            if m or time.monotonic() > deadline:
                job_id = m.group(1) if m else None
                break
        assert job_id is not None
        time.sleep(1.0)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the demo
        proc.wait()
        # and its service with the service's workers (a session of its own, so Ctrl-C reaches the demo only)
        for pid in re.findall(r"Started server process \[(\d+)\]", log.read_text() if log.exists() else ""):
            try:
                os.killpg(int(pid), signal.SIGKILL)
            except ProcessLookupError:
                pass
        time.sleep(0.5)
    with sqlite3.connect(tmp_path / "var" / "service.sqlite3") as db:
        assert db.execute("SELECT id, state FROM jobs").fetchall() in ([(job_id, "queued")],
                                                                       [(job_id, "running")])

    again = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert again.returncode == 0, again.stdout[-3000:] + again.stderr[-3000:]
    assert f"job {job_id} resumed" in again.stdout and " queued\n" not in again.stdout
    with sqlite3.connect(tmp_path / "var" / "service.sqlite3") as db:
        assert db.execute("SELECT id, state FROM jobs").fetchall() == [(job_id, "done")]
    assert (tmp_path / "out" / "store.json").is_file()
    from tools.demo import JOBS_RECORD

    record = tmp_path / "var" / JOBS_RECORD
    assert list(json.loads(record.read_text()).values()) == [job_id]
    # another request submits its own job, and the record forgets the ended one
    other = subprocess.run([*command, "--generations", "3", "--verify-frames", "0"], cwd=REPO_ROOT,
                           capture_output=True, text=True, timeout=300, check=False)
    assert other.returncode == 0, other.stdout[-3000:] + other.stderr[-3000:]
    new_id = re.search(r"job (\w+) queued", other.stdout).group(1)
    assert new_id != job_id and list(json.loads(record.read_text()).values()) == [new_id]

