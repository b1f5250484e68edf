"""Optimize power: send the scene (as the render engine renders it: the depsgraph translator at render level,
written as a render-budget scene file) and the camera path, run a job (a local job process with the bundled
core by default, or the remote service), keep the store.

GUI (invoke): the export happens on the main thread, a worker thread follows the job (no bpy), and a timer
on the main thread drains a queue into the WindowManager progress properties. Background/batch (execute):
the same steps synchronously. The store ends up in a text datablock that is saved with the .blend.
"""

from __future__ import annotations

import json
import logging
import queue
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import bpy

from service import camera_path as path_format
from service import store as pareto_store

from . import playback, preferences, service_process
from .camera_path import load_path, sample_animation, store_path
from .core.client import ServiceClient
from .core.job_runner import JobOutcome, JobRequest, JobUpdate, run_job
from .core.local_jobs import LocalClient
from .core.playback_logic import budget_shortfall, predicted_path_summary, summary_text, validate_budget
from .core.scene_translation import notes_text
from .properties import option_values, query_values
from .translate import translate_for_render

log = logging.getLogger(__name__)
STORE_TEXT_PREFIX = "render_budget_store"


# -- main-thread preparation ----------------------------------------------------------------------------
def check_scene(scene: bpy.types.Scene) -> None:
    """Fail early with a clear message on scenes the service cannot optimise."""
    if scene.camera is None:
        raise ValueError("the scene has no active camera: add one or record a viewport path")
    if not any(o.type in {"MESH", "CURVE", "SURFACE", "META", "FONT"} and not o.hide_render
               for o in scene.objects):
        raise ValueError("the scene has no renderable geometry (empty scene)")


def job_request(scene: bpy.types.Scene) -> JobRequest:
    """The job the panel describes; the parameter list's values, where edited away from the default
    ones, become the job's ``space`` (ValueError names a value the renderer does not take)."""
    # lazy: loads the native core, which registering the add-on does not
    from service.params import space_from_texts

    props = scene.render_budget
    searchable = [p for p in props.parameters if not p.inert]
    enabled = tuple(p.name for p in searchable if p.enabled)
    space = space_from_texts({p.name: p.values for p in searchable if p.enabled})
    return JobRequest(
        profile=props.profile or _default_profile(),
        # None lets the service search its whole default space (minus what is inert for this scene)
        parameters=enabled if searchable else None,
        options=option_values(props),
        space=space or None,
    )


def _default_profile() -> str:
    try:
        return preferences.get().default_profile or "mobile"
    except RuntimeError:
        return "mobile"


def export_scene(scene: bpy.types.Scene, directory: str | Path) -> Path:
    """The scene as a final render sees it (modifiers at render level, render visibility, materials, lights,
    world, camera at the current frame), translated from a render depsgraph and written as a render-budget
    scene file: exactly what the render engine renders. What the translation approximated is kept in
    ``scene.render_budget.scene_notes`` (the panel shows it) and travels inside the file to the job."""
    # lazy: the native core loads on first use, not when the add-on registers
    from sim_core.loaders.scene_file import SUFFIX, write_scene_file

    window = bpy.context.window
    with bpy.context.temp_override(scene=scene, **({"window": window} if window else {})):
        if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")  # edits in edit mode reach the depsgraph on leaving it
    translation = translate_for_render(scene)
    path = Path(directory) / f"scene{SUFFIX}"
    write_scene_file(path, translation.scene_data, translation.notes)
    scene.render_budget.scene_notes = notes_text(translation.notes, limit=len(translation.notes))
    for note in translation.warnings:
        log.warning("scene translation: %s", note)
    return path


def ensure_path(scene: bpy.types.Scene) -> path_format.CameraPath:
    """The recorded path, recording it from the active camera's animation if there is none yet."""
    path = load_path(scene)
    if path is None:
        path = sample_animation(scene, scene.camera, scene.render_budget.frame_step)
        store_path(scene, path)
    return path


@dataclass
class Prepared:
    scene_name: str
    scene_file: Path
    path: path_format.CameraPath
    request: JobRequest
    tmpdir: tempfile.TemporaryDirectory = field(repr=False)


def prepare(scene: bpy.types.Scene) -> Prepared:
    check_scene(scene)
    props = scene.render_budget
    validate_budget(props.budget_mode,
                    props.power_budget if props.budget_mode == "POWER" else props.error_budget)
    request = job_request(scene)
    path = ensure_path(scene)
    tmp = tempfile.TemporaryDirectory(prefix="render-budget-export-")
    try:
        scene_file = export_scene(scene, tmp.name)
    except Exception:
        tmp.cleanup()
        raise
    return Prepared(scene.name, scene_file, path, request, tmp)


@dataclass(frozen=True)
class Applied:
    """The results summary shown in the panel, and why the current budget cannot be met (None: it can)."""

    summary: str
    shortfall: str | None


def apply_outcome(scene: bpy.types.Scene, outcome: JobOutcome, path: path_format.CameraPath) -> Applied:
    """Keep the store in the .blend (text datablock), record ids and the results summary."""
    store = pareto_store.ParetoStore.from_json(outcome.store_text)  # validate before replacing anything
    props = scene.render_budget
    text = props.store_text
    if text is None:
        text = bpy.data.texts.new(f"{STORE_TEXT_PREFIX}_{scene.name}.json")
        text.use_fake_user = True
        props.store_text = text
    text.from_string(outcome.store_text)
    props.store_revision += 1
    props.scene_id, props.job_id, props.store_id = outcome.scene_id, outcome.job_id, outcome.store_id
    fill_parameters(scene, outcome.scene_info.get("inert_parameters") or {}, store)
    mode = props.budget_mode
    value = props.power_budget if mode == "POWER" else props.error_budget
    frames = path.frames[:: max(1, len(path.frames) // 300)]  # a few hundred poses are plenty here
    unusable = ""
    try:
        summary = predicted_path_summary(store, frames, mode, value, **query_values(props))
    except ValueError as err:  # e.g. a frame-rate target this store cannot answer: keep the store,
        # summarise it at its own rate and say why (playback says it on every frame)
        summary = predicted_path_summary(store, frames, mode, value)
        unusable = f"lookup options unusable with this store ({err}): summary at its own frame rate; "
    props.summary = unusable + summary_text(summary)
    playback.reset()
    return Applied(props.summary, budget_shortfall(summary))


def fill_parameters(scene: bpy.types.Scene, inert: dict[str, str],
                    store: pareto_store.ParetoStore | None = None) -> None:
    """Show the parameter space: the store's parameters with the values it was searched with (without a
    store: the values typed so far, else the default ones), then inert ones with their reason."""
    # lazy: loads the native core, which registering the add-on does not
    from service.params import DEFAULT_VALUES, values_text

    props = scene.render_budget
    previous = {p.name: p.enabled for p in props.parameters}
    typed = {p.name: p.values for p in props.parameters if not p.inert and p.values.strip()}
    if store is not None:
        listed = {p.name: values_text(p.values) for p in store.parameters}
    else:
        listed = {name: typed.get(name, values_text(values)) for name, values in DEFAULT_VALUES.items()}
    props.parameters.clear()
    for name, text in listed.items():
        if name in inert:
            continue  # listed below, greyed out with the reason (a store keeps it, fixed)
        _list_values(props.parameters.add(), name, text, previous.get(name, True))
    for name, reason in sorted(inert.items()):
        if name in props.parameters:
            continue
        item = props.parameters.add()
        item.name, item.inert, item.reason, item.enabled = name, True, reason, False


def set_parameter_values(scene: bpy.types.Scene, texts: list[str]) -> None:
    """``NAME=V1,V2,...`` texts (batch ``optimize --space``) into the parameter list, which the default
    values fill first when it lists none: the next job searches them and the .blend keeps them.
    ValueError names an unknown parameter or value, or a parameter inert for this scene."""
    # lazy: loads the native core, which registering the add-on does not
    from service.params import parse_space_argument, values_text

    parsed = [parse_space_argument(text) for text in texts]  # all checked before anything changes
    props = scene.render_budget
    inert = {p.name: p.reason for p in props.parameters if p.inert}
    for name, _ in parsed:
        if name in inert:
            raise ValueError(f"parameter {name!r} cannot change this scene ({inert[name]})")
    if not any(not p.inert for p in props.parameters):
        fill_parameters(scene, inert)
    for name, values in parsed:
        _list_values(props.parameters.get(name) or props.parameters.add(), name, values_text(values), True)


def _list_values(item: bpy.types.PropertyGroup, name: str, text: str, enabled: bool) -> None:
    """One searchable row of the parameter list: its name, its values as text and their count."""
    item.name, item.values, item.enabled = name, text, enabled
    item.value_count = len([v for v in text.split(",") if v.strip()])


def run_sync(scene: bpy.types.Scene, client: ServiceClient | LocalClient,
             progress: Callable[[JobUpdate], None] | None = None, timeout_s: float | None = None,
             stall_s: float | None = None) -> Applied:
    """The whole optimisation on the calling (main) thread: for background mode, batch and tests."""
    prep = prepare(scene)
    try:
        outcome = run_job(client, prep.scene_file, prep.path.to_dict(), prep.request, progress=progress,
                          timeout_s=timeout_s, stall_s=stall_s)
    finally:
        prep.tmpdir.cleanup()
    return apply_outcome(scene, outcome, prep.path)


# -- GUI: worker thread + timer -------------------------------------------------------------------------
@dataclass
class _ActiveJob:
    prep: Prepared
    thread: threading.Thread
    messages: queue.Queue = field(default_factory=queue.Queue)
    cancel: threading.Event = field(default_factory=threading.Event)


_active: _ActiveJob | None = None


def job_running() -> bool:
    return _active is not None and _active.thread.is_alive()


def _worker(job: _ActiveJob, client: ServiceClient | LocalClient) -> None:
    """Follows the job (HTTP or the local job process); never touches bpy. Posts ('progress'|'done'|'error',
    payload) messages."""
    try:
        outcome = run_job(client, job.prep.scene_file, job.prep.path.to_dict(), job.prep.request,
                          progress=lambda u: job.messages.put(("progress", u)),
                          should_cancel=job.cancel.is_set)
        job.messages.put(("done", outcome))
    except Exception as err:  # everything goes back to the main thread to be reported
        job.messages.put(("error", err))


def _redraw() -> None:
    wm = bpy.context.window_manager
    for window in wm.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def _poll_queue() -> float | None:
    """bpy.app.timers callback on the main thread: apply worker messages; stop when the job ends."""
    global _active
    job = _active
    if job is None:
        return None
    rt = bpy.context.window_manager.render_budget_runtime
    finished = False
    while True:
        try:
            kind, payload = job.messages.get_nowait()
        except queue.Empty:
            break
        if kind == "progress":
            rt.job_progress, rt.job_status = payload.fraction, payload.text
        elif kind == "done":
            scene = bpy.data.scenes.get(job.prep.scene_name)
            if scene is None:
                rt.job_status = "finished, but the scene was removed; store not kept"
            else:
                try:
                    rt.job_status = status_text(apply_outcome(scene, payload, job.prep.path))
                    rt.job_progress = 1.0
                except ValueError as err:
                    rt.job_status = f"failed: invalid store ({err})"
            finished = True
        else:
            rt.job_status = f"failed: {service_process.explain(payload)}"
            finished = True
    _redraw()
    if finished:
        rt.job_running = False
        job.prep.tmpdir.cleanup()
        _active = None
        return None
    return 0.25


def status_text(applied: Applied) -> str:
    """The job line of the panel: done, or done but the budget cannot be met (said first)."""
    if applied.shortfall:
        return f"done, but {applied.shortfall}"
    return f"done: {applied.summary}"


class RENDER_BUDGET_OT_optimize(bpy.types.Operator):
    """Optimise render settings along the camera path (locally with the bundled simulator, or on the remote
    service chosen in the preferences)"""

    bl_idname = "render_budget.optimize"
    bl_label = "Optimize Power"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return not job_running()

    def execute(self, context: bpy.types.Context) -> set[str]:
        wm = context.window_manager
        rt = wm.render_budget_runtime
        try:
            client = service_process.client_for(context)
            wm.progress_begin(0, 100)

            def progress(u: JobUpdate) -> None:
                rt.job_progress, rt.job_status = u.fraction, u.text
                wm.progress_update(int(100 * u.fraction))
                log.info("%s", u.text)

            applied = run_sync(context.scene, client, progress)
        except Exception as err:  # report every failure; the .blend keeps its previous store
            rt.job_status = f"failed: {service_process.explain(err)}"
            self.report({"ERROR"}, f"Optimize power failed: {service_process.explain(err)}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        rt.job_status = status_text(applied)
        self.report({"WARNING"} if applied.shortfall else {"INFO"}, rt.job_status)
        return {"FINISHED"}

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        global _active
        if bpy.app.background:
            return self.execute(context)
        rt = context.window_manager.render_budget_runtime
        try:
            client = service_process.client_for(context)
            prep = prepare(context.scene)
        except Exception as err:
            self.report({"ERROR"}, f"Optimize power: {service_process.explain(err)}")
            return {"CANCELLED"}
        job = _ActiveJob(prep, threading.Thread(name="render-budget-job", daemon=True))
        job.thread = threading.Thread(target=_worker, args=(job, client), name="render-budget-job",
                                      daemon=True)
        _active = job
        rt.job_running, rt.job_progress, rt.job_status = True, 0.0, "starting"
        job.thread.start()
        bpy.app.timers.register(_poll_queue, first_interval=0.25, persistent=True)  # survive file loads
        return {"FINISHED"}


class RENDER_BUDGET_OT_cancel_job(bpy.types.Operator):
    """Cancel the running optimisation (the job stops; what it evaluated stays in the evaluation cache;
    nothing in the .blend changes)"""

    bl_idname = "render_budget.cancel_job"
    bl_label = "Cancel"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return job_running()

    def execute(self, context: bpy.types.Context) -> set[str]:
        if _active is not None:
            _active.cancel.set()
            context.window_manager.render_budget_runtime.job_status = "cancelling"
        return {"FINISHED"}


class RENDER_BUDGET_OT_load_store(bpy.types.Operator):
    """Load a Pareto store from a JSON file (e.g. written by `render-budget optimize`) into the .blend"""

    bl_idname = "render_budget.load_store"
    bl_label = "Load Store File"

    filepath: bpy.props.StringProperty(subtype="FILE_PATH")  # type: ignore[valid-type]

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            text = Path(bpy.path.abspath(self.filepath)).read_text(encoding="utf-8")
            json.loads(text)
            pareto_store.ParetoStore.from_json(text)
        except (OSError, ValueError) as err:
            self.report({"ERROR"}, f"not a usable store: {err}")
            return {"CANCELLED"}
        scene = context.scene
        path = load_path(scene)
        if path is None:
            self.report({"ERROR"}, "record a camera path first (the summary is computed along it)")
            return {"CANCELLED"}
        outcome = JobOutcome("", scene.render_budget.scene_id, "", text)
        applied = apply_outcome(scene, outcome, path)
        self.report({"WARNING"} if applied.shortfall else {"INFO"}, status_text(applied))
        return {"FINISHED"}

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


classes = (RENDER_BUDGET_OT_optimize, RENDER_BUDGET_OT_cancel_job, RENDER_BUDGET_OT_load_store)
_register, _unregister = bpy.utils.register_classes_factory(classes)


def register() -> None:
    _register()


def unregister() -> None:
    global _active
    if _active is not None:
        _active.cancel.set()
        _active = None
    if bpy.app.timers.is_registered(_poll_queue):
        bpy.app.timers.unregister(_poll_queue)
    _unregister()
