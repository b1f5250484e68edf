"""Evaluate Path: the evaluation campaign of ``make demo`` (``core.campaign``) on the scene's store, path
and budgets; writes the same report folder (Table 3, per-frame CSV, plots, sample frames, store, summary).
Verify Store: the store's predictions against renders of sampled path frames at the path's resolution
(``service.verify``), verify.md and verify.json."""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import bpy

from service import options as option_schema

from . import service_process
from .camera_path import load_path
from .core import campaign, campaign_targets
from .core import report as report_data
from .core.client import ServiceClient
from .core.local_jobs import LocalClient
from .core.playback_logic import validate_budget
from .ops_preview import upload_scene_info
from .properties import query_values

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


def _store_and_path(scene: bpy.types.Scene) -> tuple:
    """The scene's render-budget properties and camera path, or a ValueError saying what is missing."""
    props = scene.render_budget
    if props.store_text is None:
        raise ValueError("no Pareto store in this .blend: run Optimize Power first")
    path = load_path(scene)
    if path is None:
        raise ValueError("no camera path recorded")
    return props, path


def evaluate_scene(scene: bpy.types.Scene, client: ServiceClient | LocalClient, out_dir: str | Path, *,
                   progress: Callable[[int, int], None] | None = None, frame_step: int | None = None,
                   samples: bool = True) -> dict:
    """Run the evaluation campaign (the same as ``make demo``'s) for a scene with a store and a path,
    under the scene's power and error budgets and its query options (frame-rate target, priority); return
    the written files."""
    props, path = _store_and_path(scene)
    budgets = validate_budget("ERROR", props.error_budget), validate_budget("POWER", props.power_budget)
    info = upload_scene_info(scene, client)
    searched_at = option_schema.eval_resolution(props.eval_width or None, props.eval_height,
                                                path.frames[0].aspect)
    measured_at, power_at = campaign.measurement_sizes(props.store_text.as_string(), searched_at, path)
    spec = campaign.CampaignSpec(
        scene_id=str(info["id"]), profile=props.profile or None, resolution=measured_at,
        power_resolution=power_at,
        frame_step=frame_step or props.report_frame_step, filter_period_s=props.filter_period,
        error_budget=budgets[0], power_budget=budgets[1], samples=3 if samples else 0, **query_values(props))
    name = Path(bpy.data.filepath).stem or "untitled"
    pre = campaign_targets.Preprocessing(f"{name} / {scene.name}", (info.get("stats") or {}).get("triangles"))
    outcome = campaign.run(client, props.store_text.as_string(), path, spec, out_dir, title=pre.name, pre=pre,
                           progress=None if progress is None else lambda _label, d, t: progress(d, t),
                           say=log.info)
    written = dict(outcome.written)
    if "plots_skipped" in written:
        python = _plot_elsewhere(Path(written["csv"]), Path(out_dir))
        if python:
            written.pop("plots_skipped")
            written["plotted_with"] = python
    written["frames"] = outcome.samples
    written["summary"] = Path(out_dir) / "summary.json"
    return written


def verify_scene(scene: bpy.types.Scene, client: ServiceClient | LocalClient, out_dir: str | Path, *,
                 frames: int = 8) -> dict:
    """The store's predictions against renders of ``frames`` path frames at the path's resolution, under
    the scene's active budget and query options (``service.verify``: on this computer, or POST
    /stores/{id}/verify on the remote service); writes verify.md and verify.json to ``out_dir`` and
    returns the report."""
    props, path = _store_and_path(scene)
    mode = props.budget_mode
    value = validate_budget(mode, props.power_budget if mode == "POWER" else props.error_budget)
    payload: dict = {"camera_path": path.to_dict(), "frames": int(frames),
                     ("power_budget_w" if mode == "POWER" else "error_budget"): value}
    # the query options the scene changes (left out at their defaults: a service from before them
    # accepts the request)
    payload.update(option_schema.only_query_overrides(query_values(props)))
    if isinstance(client, LocalClient):
        payload["scene_id"] = str(upload_scene_info(scene, client)["id"])
        doc = client.verify_text(props.store_text.as_string(), payload)
    else:
        if not props.store_id:
            raise ValueError("this store did not come from the service: verify it on this computer")
        doc = client.verify(props.store_id, payload, timeout_s=3600.0)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "verify.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
    from service.verify import markdown  # lazy: service.verify loads the native core

    (out / "verify.md").write_text(markdown(doc) + "\n", encoding="utf-8")
    return doc


class RENDER_BUDGET_OT_verify_store(bpy.types.Operator):
    """Render sampled path frames at the path's resolution with the store's settings and compare the
    measured error and power with its predictions"""

    bl_idname = "render_budget.verify_store"
    bl_label = "Verify Store"

    directory: bpy.props.StringProperty(subtype="DIR_PATH")  # type: ignore[valid-type]
    frames: bpy.props.IntProperty(name="Frames", default=8, min=1, max=32)  # type: ignore[valid-type]

    def execute(self, context: bpy.types.Context) -> set[str]:
        out = bpy.path.abspath(self.directory) if self.directory else \
            bpy.utils.extension_path_user(__package__, path="reports", create=True)
        try:
            doc = verify_scene(context.scene, service_process.client_for(context), out, frames=self.frames)
        except Exception as err:  # report, the .blend is untouched
            self.report({"ERROR"}, f"Verify store failed: {service_process.explain(err)}")
            return {"CANCELLED"}
        s = doc["summary"]
        self.report({"INFO"}, f"{s['within_budget']}/{s['frames']} frames within budget at "
                              f"{doc['resolution'][0]}x{doc['resolution'][1]}; mean error difference "
                              f"{s['mean_abs_error_difference']:.4f}, power measured/predicted "
                              f"{s['median_power_ratio']:.2f} (verify.md in {out})")
        return {"FINISHED"}


class RENDER_BUDGET_OT_evaluate_path(bpy.types.Operator):
    """Measure the path with the presets and the store under both budgets; write a report folder"""

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


classes = (RENDER_BUDGET_OT_evaluate_path, RENDER_BUDGET_OT_verify_store)
register, unregister = bpy.utils.register_classes_factory(classes)
