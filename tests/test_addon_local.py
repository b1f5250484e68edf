"""The add-on with its default set-up: jobs on this computer with the bundled core (a child process per
job, started with this interpreter), no service and no preferences to fill in. Optimize (synchronous and
the GUI's worker-thread path), cancel, and a full-HD preview rendered in-process, band by band."""

from __future__ import annotations

import csv
import importlib
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest

from tests import orbit_scene
from tests.addon_support import (
    EXT_MODULE,
    cancel_gui_job,
    disable_dev,
    enable_dev,
    stage_extension,
    start_gui_job,
)

pytestmark = [pytest.mark.blender, pytest.mark.slow]
bpy = pytest.importorskip("bpy")


@pytest.fixture(scope="module")
def ext(tmp_path_factory: pytest.TempPathFactory):
    mod = enable_dev(bpy, stage_extension(tmp_path_factory.mktemp("ext")))
    prefs = m("preferences").get()
    assert prefs.service_mode == "LOCAL"  # the default: nothing to set up
    prefs.local_workers = 1
    prefs.data_dir = str(tmp_path_factory.mktemp("local-data"))
    yield mod
    disable_dev()


def m(name: str):
    return importlib.import_module(f"{EXT_MODULE}.{name}")


def job_processes() -> list[int]:
    """Live processes below this one running the local job module (Linux /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{entry}/cmdline", "rb") as fh:
                cmd = fh.read()
        except OSError:
            continue
        if fields[0] != "Z" and int(fields[1]) == os.getpid() and b"service.local_job" in cmd:
            out.append(int(entry))
    return out


def scene() -> bpy.types.Scene:
    sc = orbit_scene.build(bpy, 16, (96, 54))
    orbit_scene.small_job(sc.render_budget)
    return sc


def test_optimize_and_evaluate_run_here_by_default_and_leave_no_process(ext, tmp_path) -> None:
    sc = scene()
    assert bpy.ops.render_budget.optimize() == {"FINISHED"}
    props = sc.render_budget
    rt = bpy.context.window_manager.render_budget_runtime
    assert rt.job_status.startswith("done"), rt.job_status
    doc = json.loads(props.store_text.as_string())
    assert doc["meta"]["views_optimised"] > 0 and props.job_id and props.store_id
    assert m("service_process").local_job_pids() == [] and job_processes() == []
    data = Path(m("preferences").get().data_dir)  # the scene as a scene file, the evaluation cache
    assert (data / "cache" / "eval_cache.sqlite3").is_file() and any((data / "scenes").glob("*.rbscene"))
    sc.frame_set(5)  # the store drives playback
    assert props.playback_status in ("on target", "blending") and props.active_indices
    props.report_frame_step = 4
    out = tmp_path / "report"
    assert bpy.ops.render_budget.evaluate_path(directory=str(out)) == {"FINISHED"}
    with (out / "per_frame.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 * 6  # 4 frames x (4 presets + ours under each budget), measured here
    assert {r["mode"] for r in rows} == {"max", "max_mid", "mid_min", "min", "ours_power", "ours_error"}
    assert (out / "report.md").is_file() and (out / "summary.json").is_file()
    assert len(list((out / "frames").glob("*.png"))) >= 4 and list((out / "frames").glob("*.exr"))
    # Verify Store: sampled path frames at the path's 96x54 with the store's settings, measured here
    props.budget_mode, props.error_budget = "ERROR", 0.02
    assert bpy.ops.render_budget.verify_store(directory=str(out), frames=3) == {"FINISHED"}
    doc = json.loads((out / "verify.json").read_text())
    assert doc["resolution"] == [96, 54] and len(doc["frames"]) == 3 and doc["budget_mode"] == "error"
    assert doc["store_figures_resolution"] == [96, 54]  # the store was priced at the path's size
    assert doc["summary"]["within_budget"] == sum(f["measured_error"] <= 0.02 for f in doc["frames"])
    assert "within budget" in (out / "verify.md").read_text()
    assert job_processes() == []


def test_gui_path_follows_the_local_job_to_the_store(ext) -> None:
    sc = scene()
    sc.render_budget.seed = 7
    ops, job = start_gui_job(bpy)
    job.thread.join(600)
    assert not job.thread.is_alive()
    assert ops._poll_queue() is None
    rt = bpy.context.window_manager.render_budget_runtime
    assert rt.job_status.startswith("done"), rt.job_status
    assert rt.job_progress == 1.0 and sc.render_budget.store_text is not None
    assert job_processes() == []


def test_cancel_from_the_gui_path_stops_the_job_process(ext) -> None:
    sc = scene()
    props = sc.render_budget
    # a search no machine finishes in the half second before Cancel (the exhaustive enumeration of the
    # small job's space could, from the evaluation cache the tests before this one filled)
    props.seed, props.max_depth, props.population, props.generations = 12345, 2, 64, 500
    props.exhaustive_limit = 0
    ops, job = start_gui_job(bpy)
    deadline = time.monotonic() + 120
    while not job_processes() and time.monotonic() < deadline:
        time.sleep(0.02)
    running = job_processes()
    assert running  # the job runs in a child process of this one
    # its camera references go to its own folder in the data folder, not the system's temporary one
    jobs = Path(m("preferences").get().data_dir) / "jobs"
    while not list(jobs.glob("*/scratch/render-budget-references-*")) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert list(jobs.glob("*/scratch/render-budget-references-*"))
    time.sleep(0.5)
    rt = cancel_gui_job(bpy, ops, job)
    assert "cancelled" in rt.job_status and props.store_text is None
    deadline = time.monotonic() + 30
    while job_processes() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert job_processes() == []
    # and a cancelled job leaves none of them behind, however it ended
    deadline = time.monotonic() + 10
    while list(jobs.glob("*/scratch")) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert list(jobs.glob("*/scratch")) == []


def test_preview_renders_full_hd_here_in_bands(ext) -> None:
    """The scene's 1920x1080 at scale 1: no size limit below what memory holds; the image is the one
    sim_core.render gives."""
    sc = orbit_scene.build(bpy, 4, (1920, 1080))
    sc.frame_set(3)
    fractions: list[float] = []
    image = m("ops_preview").render_preview(sc, use_active=False, scale=1.0, progress=fractions.append)
    assert tuple(image.size) == (1920, 1080) and image.packed_file is not None
    assert len(fractions) > 10 and fractions[-1] == 1.0 and fractions == sorted(fractions)
    meta = json.loads(image["render_budget"])
    assert meta["energy"]["power_w"] > 0 and meta["counters"]["pixels"] == 1920 * 1080
    e = meta["energy"]  # power drawn at the rate reached: max quality at 1080p misses the scene's fps
    assert e["achieved_fps"] == (e["fps"] if e["deadline_met"] else pytest.approx(e["max_fps"]))
    # Maximum quality: FSAA 2x2, plus the pixel filter's guard ring of 2 sub-samples around the frame.
    assert meta["counters"]["samples_traced"] == (2 * 1920 + 4) * (2 * 1080 + 4)
    px = np.empty(1920 * 1080 * 4, dtype=np.float32)
    image.pixels.foreach_get(px)
    rgb = px.reshape(1080, 1920, 4)[::-1, :, :3]
    assert np.isfinite(rgb).all() and rgb.max() > 0.05 and rgb.std() > 0.01  # a lit box, not a flat frame


def test_a_preview_can_be_cancelled_and_is_refused_beyond_memory(ext) -> None:
    sc = orbit_scene.build(bpy, 4, (640, 360))
    sc.frame_set(2)
    ops_preview = m("ops_preview")
    job = ops_preview.prepare(sc, use_active=False)
    job.cancel.set()  # as Esc does in the GUI, checked after every band
    job.run()
    assert isinstance(job.error, m("core.preview").PreviewCancelled) and job.result is None
    with pytest.raises(ValueError, match=r"needs about .* GiB of memory and 0\.5 GiB are available"):
        m("core.preview").check_size(16384, 16384, available=2**29)


def test_analyse_scene_runs_here(ext) -> None:
    sc = scene()
    assert bpy.ops.render_budget.analyze_scene() == {"FINISHED"}
    inert = {p.name for p in sc.render_budget.parameters if p.inert}
    assert "multirate" in inert or "normal_threshold_deg" in inert  # the simulator said why


def test_the_parameter_list_lists_the_default_values_and_a_job_searches_what_it_is_edited_to(ext) -> None:
    """Before any store the list shows the default values of the parameters that can change the scene;
    editing one makes the next job search those values (its ``space``), and a value the renderer does
    not take stops the job before anything is sent, naming it."""
    from service.params import DEFAULT_VALUES, values_text

    ops = m("ops_optimize")
    sc = orbit_scene.build(bpy, 8, (96, 54))  # no parameters listed yet
    assert bpy.ops.render_budget.analyze_scene() == {"FINISHED"}
    props = sc.render_budget
    listed = {p.name: p.values for p in props.parameters if not p.inert}
    inert = {p.name for p in props.parameters if p.inert}
    assert listed and set(listed) | inert == set(DEFAULT_VALUES) and not set(listed) & inert
    assert all(text == values_text(DEFAULT_VALUES[name]) for name, text in listed.items())
    assert ops.job_request(sc).space is None  # untouched: the default space
    props.parameters["shadow_samples"].values = "0, 1, 2, 4, 16"
    assert ops.job_request(sc).space == {"shadow_samples": (0, 1, 2, 4, 16)}
    assert bpy.ops.render_budget.analyze_scene() == {"FINISHED"}  # analysing again keeps the edit
    assert props.parameters["shadow_samples"].values == "0, 1, 2, 4, 16"
    props.parameters["shadow_samples"].values = "0, 3"
    with pytest.raises(RuntimeError, match="'3' is not a value of 'shadow_samples'"):
        bpy.ops.render_budget.optimize()
    assert props.store_text is None

