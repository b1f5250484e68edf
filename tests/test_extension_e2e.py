"""The extension as an artist gets it: the zip built by `make addon`, installed into a fresh Blender user
folder of a virtual environment that holds only bpy (a stand-in for a stock Blender: never this project),
then, in background mode and nothing else configured: a small scene with a keyframed camera, the path
recorded, Optimize Power with small options (a local job process of the venv's Python), playback under a
power budget, one frame rendered with the Render Budget GPU engine under that store and budget (in its own
step, after playback: background mode draws nothing), a second job left running while the extension is
disabled, and no child process left.

The script runs its steps in order (`STEPS`); a new step is a function that returns a dict of what it saw
plus a line in `STEPS`, and its checks go in the test below.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from tests import bpy_venv
from tests.addon_support import kill_and_check_nothing_left

pytestmark = [pytest.mark.blender, pytest.mark.slow]

WATCHER = r'''
"""Polls the process tree below the pid given until stdin closes; writes every command line seen. The
test script imports its descendants()."""
import json, os, select, sys


def descendants(root):
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
                with open(f"/proc/{entry}/cmdline", "rb") as fh:
                    argv = [a.decode(errors="replace") for a in fh.read().split(b"\0") if a]
            except OSError:
                continue
            if fields[0] != "Z":
                parents.setdefault(int(fields[1]), []).append((int(entry), argv))
    out, todo = [], [root]
    while todo:
        for pid, argv in parents.get(todo.pop(), []):
            out.append((pid, argv))
            todo.append(pid)
    return out


if __name__ == "__main__":
    root, me, seen = int(sys.argv[1]), os.getpid(), set()
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    while True:
        seen.update(tuple(argv) for pid, argv in descendants(root) if pid != me)
        if select.select([sys.stdin], [], [], 0.02)[0]:
            break
    with open(sys.argv[2], "w", encoding="utf-8") as fh:
        json.dump(sorted(seen), fh)
'''

SCRIPT = r'''
import json, os, subprocess, sys, threading, time
import bpy, addon_utils
import orbit_scene  # copied next to this script: bpy only
import watcher  # written next to this script: the process tree, stdlib only

ZIP = sys.argv[1]
MOD = "bl_ext.user_default.render_budget"


def ext(name):
    import importlib
    return importlib.import_module(f"{MOD}.{name}")


def descendants():
    """Live processes below this one: (pid, argv)."""
    return watcher.descendants(os.getpid())


class Watch:
    """Command lines seen below this one while a step runs (a process is first seen with its parent's
    command line, between fork and exec: every one seen is kept). The polling runs in a separate process:
    a Python thread of this one running while bpy.ops.render.render holds Blender (the translation's
    render) crashed Blender now and then."""

    def __enter__(self):
        self.out = os.path.abspath(f"watch-{time.monotonic_ns()}.json")
        self.proc = subprocess.Popen([sys.executable, "-I", os.path.abspath("watcher.py"), str(os.getpid()),
                                      self.out], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        assert self.proc.stdout.readline() == b"ready\n"
        return self

    def __exit__(self, *exc):
        self.proc.stdin.close()
        self.proc.wait(30)
        with open(self.out, encoding="utf-8") as fh:
            self.seen = {tuple(argv) for argv in json.load(fh)}


def install():
    res = bpy.ops.extensions.package_install_files(filepath=ZIP, repo="user_default", enable_on_install=True)
    import service, sim_core
    prefs = ext("preferences").get()
    prefs.local_workers = 2  # a job with evaluation workers, whose end is checked below
    return {"result": sorted(res), "enabled": MOD in bpy.context.preferences.addons,
            "service": service.__file__, "sim_core": sim_core.__file__, "mode": prefs.service_mode,
            "url": prefs.url}


def scene():
    sc = orbit_scene.build(bpy, 12, (96, 54))
    orbit_scene.small_job(sc.render_budget)
    anim = sc.camera.animation_data
    return {"camera": sc.camera.name, "keyed": bool(anim and anim.action)}


def record():
    res = bpy.ops.render_budget.record_path_animation()
    path = json.loads(bpy.context.scene.render_budget.path_text.as_string())
    return {"result": sorted(res), "frames": len(path["frames"])}


def optimize():
    with Watch() as watch:
        res = bpy.ops.render_budget.optimize()
    props = bpy.context.scene.render_budget
    store = json.loads(props.store_text.as_string()) if props.store_text else {}
    jobs = sorted(argv for argv in watch.seen if any("service.local_job" in a for a in argv))
    workers = {argv for argv in watch.seen if any("multiprocessing.spawn" in a for a in argv)}
    return {"result": sorted(res), "status": bpy.context.window_manager.render_budget_runtime.job_status,
            "views": store.get("meta", {}).get("views_optimised", 0), "job_argv": jobs[:1],
            "workers": len(workers), "python": sys.executable, "left": descendants()}


def playback():
    sc = bpy.context.scene
    props = sc.render_budget
    from service.store import ParetoStore
    store = ParetoStore.from_json(props.store_text.as_string())
    powers = sorted({float(p) for f in store.frontiers for p in f.power_w})
    budget = powers[len(powers) // 2]  # the middle of what the store offers
    props.budget_mode, props.power_budget = "POWER", budget
    frames = []
    for f in range(sc.frame_start, sc.frame_end + 1):
        sc.frame_set(f)
        frames.append({"frame": f, "status": props.playback_status, "power": props.predicted_power,
                       "infeasible": props.infeasible, "settings": props.active_settings})
    return {"budget": budget, "frames": frames}


def png_text(path):
    """The text chunks of a PNG (the metadata Blender writes; stdlib only, no Pillow in this venv)."""
    import struct
    data, out, at = open(path, "rb").read(), {}, 8
    while at < len(data):
        (size,), kind = struct.unpack(">I", data[at:at + 4]), data[at + 4:at + 8]
        if kind == b"tEXt":
            key, _, value = data[at + 8:at + 8 + size].partition(b"\0")
            out[key.decode("latin-1")] = value.decode("latin-1")
        at += 12 + size
    return out


def render_engine():
    """One frame with the Render Budget GPU engine, under the store and the budget playback used."""
    sc = bpy.context.scene
    sc.render.engine = "RENDER_BUDGET"
    sc.render.image_settings.file_format = "PNG"
    sc.render.filepath = os.path.abspath("engine_frame.png")
    sc.frame_set(sc.frame_start + 3)
    res = bpy.ops.render.render(write_still=True)
    last = ext("engine.render").last_frame
    if last is None:  # the engine reported an error instead of a frame (on the log the test shows)
        return {"result": sorted(res), "passes": []}
    meta = png_text(sc.render.filepath)
    return {"result": sorted(res), "passes": list(last.layer_passes), "source": last.output.settings.source,
            "size": list(last.output.combined.shape), "power": last.output.power_w,
            "playback_power": sc.render_budget.predicted_power,
            "predicted": last.output.settings.predicted_power_w,
            "meta": {k: v for k, v in meta.items() if k.startswith("render_budget.")}}


def start_long_job():
    """Optimize Power as the button starts it (a worker thread follows the job); returns when the job
    process and its two evaluation workers are at work."""
    sc = bpy.context.scene
    props = sc.render_budget
    props.seed, props.max_depth, props.population, props.generations = 99, 2, 16, 20
    ops = ext("ops_optimize")
    client = ext("service_process").client_for(bpy.context)
    job = ops._ActiveJob(ops.prepare(sc), threading.Thread())
    job.thread = threading.Thread(target=ops._worker, args=(job, client), daemon=True)
    ops._active = job
    job.thread.start()
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if len([1 for _, argv in descendants() if "multiprocessing.spawn" in " ".join(argv)]) >= 2:
            break
        time.sleep(0.02)
    return job


def disable_mid_job():
    """A job still running when the extension is disabled (Blender closing a session does the same)."""
    job = start_long_job()
    running = descendants()
    addon_utils.disable(MOD, default_set=True)
    job.thread.join(60)
    return {"running_before": len(running), "enabled": MOD in bpy.context.preferences.addons,
            "thread_alive": job.thread.is_alive()}


def no_children():
    deadline = time.monotonic() + 15
    while descendants() and time.monotonic() < deadline:
        time.sleep(0.1)
    return {"left": descendants()}


STEPS = [install, scene, record, optimize, playback, render_engine, disable_mid_job, no_children]

if sys.argv[2:] == ["--killed-mid-job"]:  # a job at work, then this process waits to be killed
    install()
    scene()
    start_long_job()
    sys.stdout.write("RUNNING " + json.dumps([pid for pid, _ in descendants()]) + "\n")
    sys.stdout.flush()
    time.sleep(600)
out = {}
for step in STEPS:
    t0 = time.monotonic()
    out[step.__name__] = step()
    out[step.__name__]["seconds"] = round(time.monotonic() - t0, 2)
sys.stdout.write("RESULT " + json.dumps(out) + "\n")
'''


def test_zip_in_a_bpy_only_environment_optimises_plays_back_and_leaves_nothing_running(
        extension_zip: Path, tmp_path: Path) -> None:
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(Path(__file__).with_name("orbit_scene.py"), work / "orbit_scene.py")
    (work / "watcher.py").write_text(WATCHER, encoding="utf-8")
    user = tmp_path / "user"
    out, log = bpy_venv.run_script(SCRIPT, [str(extension_zip)], user, work, timeout_s=900)
    venv_python = str(bpy_venv.python())

    step = out["install"]
    assert step["result"] == ["FINISHED"] and step["enabled"], log
    site = str(user / "extensions" / ".local")
    assert step["service"].startswith(site) and step["sim_core"].startswith(site)  # from the zip's wheels
    assert step["mode"] == "LOCAL" and step["url"] == ""  # the default needs nothing set up

    assert out["scene"]["keyed"]
    assert out["record"] == {"result": ["FINISHED"], "frames": 12, "seconds": out["record"]["seconds"]}

    step = out["optimize"]
    assert step["result"] == ["FINISHED"] and step["status"].startswith("done"), (step, log)
    assert step["views"] > 0
    [job_argv] = step["job_argv"]  # the job ran in a child process of Blender's own Python
    assert job_argv[0] == step["python"] and step["python"].startswith(str(bpy_venv.venv_dir()))
    assert Path(job_argv[0]).resolve() == Path(venv_python).resolve()
    assert step["workers"] >= 2 and step["left"] == []

    step = out["playback"]
    budget = step["budget"]
    assert len(step["frames"]) == 12
    for frame in step["frames"]:
        assert frame["status"] in ("on target", "blending"), frame
        assert frame["settings"] and not frame["infeasible"]
        if frame["status"] == "on target":
            # (predicted_power is a Blender float property: float32, 6e-8 relative)
            assert frame["power"] <= budget * (1 + 1e-6), frame
    assert len({f["settings"] for f in step["frames"]}) >= 1

    step = out["render_engine"]  # the engine renders in-process on the zip's core, under the store
    assert step["result"] == ["FINISHED"], (step, log)
    assert step["passes"] == ["Combined", "Depth", "Normal", "IndexOB", "Sample Kind", "Power"], (step, log)
    assert step["size"] == [54, 96, 4] and step["source"] == "store" and step["power"] > 0
    assert step["predicted"] == pytest.approx(step["playback_power"], rel=1e-5)  # playback's choice here
    assert step["meta"]["render_budget.source"] == "store" and step["meta"]["render_budget.settings"]
    assert float(step["meta"]["render_budget.simulated_power_w"]) == pytest.approx(step["power"], rel=1e-5)

    step = out["disable_mid_job"]
    assert step["running_before"] >= 3 and not step["enabled"] and not step["thread_alive"]
    assert out["no_children"]["left"] == [], out["no_children"]


def test_killing_blender_mid_job_leaves_no_process(extension_zip: Path, tmp_path: Path) -> None:
    """Blender SIGKILLed while a local job and its workers render: no clean-up code of ours runs, and
    still nothing is left (the job reads end of file on its lifeline and kills its process group)."""
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(Path(__file__).with_name("orbit_scene.py"), work / "orbit_scene.py")
    (work / "script.py").write_text(SCRIPT, encoding="utf-8")
    (work / "watcher.py").write_text(WATCHER, encoding="utf-8")
    blender = subprocess.Popen([str(bpy_venv.python()), "script.py", str(extension_zip), "--killed-mid-job"],
                               cwd=work, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               # what a killed Blender cannot remove (its scene export) stays in here
                               env=bpy_venv.clean_env(BLENDER_USER_RESOURCES=str(tmp_path / "user"),
                                                      TMPDIR=str(work)))
    try:
        line = ""
        while not line.startswith("RUNNING "):
            line = blender.stdout.readline()
            assert line, "the script ended before its job ran"
        kill_and_check_nothing_left(blender, json.loads(line[len("RUNNING "):]))
    finally:
        if blender.poll() is None:
            blender.kill()
