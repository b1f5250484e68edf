"""Evaluate path: every frame with the fixed presets and with the optimised settings, measured by the
service, written as a report folder (Table 3, per-frame CSV, plots, sample frames)."""

from __future__ import annotations

import base64
import logging
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import bpy

from service import options as option_schema
from service import store as pareto_store

from . import service_process
from .camera_path import load_path
from .core import report as report_data
from .core.client import ServiceClient
from .core.evaluate_path import EvalSpec, camera_payload, evaluate_path, preset_settings
from .core.playback_logic import PlaybackDriver, validate_budget
from .ops_preview import upload_scene

log = logging.getLogger(__name__)


def _plot_elsewhere(csv_path: Path, out_dir: Path) -> str | None:
    """Stock Blender lacks matplotlib: draw the plots with a system Python that has it, if any."""
    candidates = [shutil.which("python3") or ""]
    script = Path(report_data.__file__)
    for python in filter(None, candidates):
        proc = subprocess.run([python, str(script), "plot", str(csv_path), str(out_dir)], capture_output=True,
                              text=True, timeout=300, check=False)
        if proc.returncode == 0:
            return python
    return None


def sample_frames(client: ServiceClient, store: pareto_store.ParetoStore, path, spec: EvalSpec,
                  out_dir: Path, count: int = 3) -> list[Path]:
    """A few frames (first, middle, last) rendered with the optimised and the maximum settings, as PNG."""
    out_dir.mkdir(parents=True, exist_ok=True)
    picks = sorted({0, len(path) // 2, len(path) - 1})[:count]
    driver = PlaybackDriver(store, 0.0)  # unfiltered target at each picked frame
    written = []
    for i in picks:
        f = path.frames[i]
        ours = driver.step(f.matrix_world, f.vfov, f.aspect, f.time, spec.budget_mode, spec.budget_value)
        for label, settings in (("ours", ours.active_settings), ("max", preset_settings(store)["max"])):
            img = client.render({"scene_id": spec.scene_id, "camera": camera_payload(f, spec.resolution),
                                 "settings": settings, "profile": spec.profile, "fps": path.fps,
                                 "format": "png"})
            target = out_dir / f"frame{i:05d}_{label}.png"
            target.write_bytes(img.data if isinstance(img.data, bytes) else base64.b64decode(img.data))
            written.append(target)
    return written


def evaluate_scene(scene: bpy.types.Scene, client: ServiceClient, out_dir: str | Path, *,
                   progress: Callable[[int, int], None] | None = None, frame_step: int | None = None,
                   samples: bool = True) -> dict:
    """Run the whole evaluation for a scene with a store and a path; return the written files."""
    props = scene.render_budget
    if props.store_text is None:
        raise ValueError("no Pareto store in this .blend: run Optimize Power first")
    path = load_path(scene)
    if path is None:
        raise ValueError("no camera path recorded")
    mode = props.budget_mode
    value = validate_budget(mode, props.power_budget if mode == "POWER" else props.error_budget)
    store = pareto_store.ParetoStore.from_json(props.store_text.as_string())
    scene_id = upload_scene(scene, client)
    step = frame_step or props.report_frame_step
    spec = EvalSpec(scene_id=scene_id, profile=props.profile or store.profile,
                    resolution=option_schema.eval_resolution(props.eval_width or None, props.eval_height,
                                                             path.frames[0].aspect),
                    budget_mode=mode, budget_value=value,
                    filter_period_s=props.filter_period, frame_step=step,
                    power_resolution=path.frames[0].resolution)
    frames = [scene.frame_start + round(path.frames[i].time * path.fps) for i in range(0, len(path), step)]
    rows = evaluate_path(client, store, path, spec, progress=progress, frames=frames)
    out = Path(out_dir)
    written = report_data.write_report(out, rows, title=f"{Path(bpy.data.filepath).stem or 'untitled'} / "
                                       f"{scene.name}", budget=(mode, value),
                                       notes=[f"store: {props.summary}", f"frames evaluated: {len(frames)}",
                                              f"evaluation resolution: {spec.resolution[0]}x"
                                              f"{spec.resolution[1]}; power at the path's resolution "
                                              f"{path.frames[0].resolution[0]}x{path.frames[0].resolution[1]}"
                                              " (dynamic power scaled by the pixel count, as the store "
                                              "predicts it)"])
    if "plots_skipped" in written:
        python = _plot_elsewhere(Path(written["csv"]), out)
        if python:
            written.pop("plots_skipped")
            written["plotted_with"] = python
    (out / "store.json").write_text(props.store_text.as_string(), encoding="utf-8")
    if samples:
        written["frames"] = sample_frames(client, store, path, spec, out / "frames")
    return written


class RENDER_BUDGET_OT_evaluate_path(bpy.types.Operator):
    """Render every path frame with the presets and the optimised settings; write a report folder"""

    bl_idname = "render_budget.evaluate_path"
    bl_label = "Evaluate Path"

    directory: bpy.props.StringProperty(subtype="DIR_PATH")  # type: ignore[valid-type]

    def execute(self, context: bpy.types.Context) -> set[str]:
        wm = context.window_manager
        out = bpy.path.abspath(self.directory) if self.directory else \
            bpy.utils.extension_path_user(__package__, path="reports", create=True)
        wm.progress_begin(0, 100)
        try:
            client = service_process.client_for(context)
            written = evaluate_scene(context.scene, client, out,
                                     progress=lambda d, t: wm.progress_update(int(100 * d / max(t, 1))))
        except Exception as err:  # report, the .blend is untouched
            self.report({"ERROR"}, f"Evaluate path failed: {service_process.explain(err)}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        msg = f"report written to {written['report']}"
        if "plots_skipped" in written:
            msg += f" (plots skipped: {written['plots_skipped']})"
        self.report({"INFO"}, msg)
        return {"FINISHED"}

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if bpy.app.background:
            return self.execute(context)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


classes = (RENDER_BUDGET_OT_evaluate_path,)
register, unregister = bpy.utils.register_classes_factory(classes)
