"""Preview: render the current frame with the simulator through the service into an Image datablock."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import bpy

from . import service_process
from .camera_path import camera_vfov, render_resolution
from .core.client import ServiceClient
from .core.vendored import pareto_store
from .ops_optimize import check_scene, export_scene, fill_parameters

IMAGE_NAME = "Power Budget Preview"


def active_settings(scene: bpy.types.Scene) -> dict[str, Any] | None:
    """The settings playback applied on this frame (None: none yet, i.e. maximum quality)."""
    props = scene.render_budget
    if props.store_text is None or not props.active_indices:
        return None
    store = pareto_store.ParetoStore.from_json(props.store_text.as_string())
    indices = [int(v) for v in props.active_indices.split()]
    return store.settings_of(indices)


def upload_scene(scene: bpy.types.Scene, client: ServiceClient) -> str:
    """Export and upload (the service deduplicates by content hash); remember the id."""
    return str(upload_scene_info(scene, client)["id"])


def upload_scene_info(scene: bpy.types.Scene, client: ServiceClient) -> dict[str, Any]:
    """Export and upload; returns the service's answer (id, statistics, inert parameters)."""
    with tempfile.TemporaryDirectory(prefix="render-budget-upload-") as tmp:
        info = client.upload_scene(export_scene(scene, tmp))
    scene.render_budget.scene_id = str(info["id"])
    return info


def render_preview(scene: bpy.types.Scene, client: ServiceClient, *, use_active: bool = True,
                   fmt: str = "PNG", scale: float = 0.25) -> bpy.types.Image:
    check_scene(scene)
    cam = scene.camera
    w, h = render_resolution(scene)
    w, h = max(4, min(4096, round(w * scale))), max(4, min(4096, round(h * scale)))
    settings = active_settings(scene) if use_active else None
    scene_id = upload_scene(scene, client)
    m = [list(row) for row in cam.matrix_world]
    m[3] = [0.0, 0.0, 0.0, 1.0]
    body = {"scene_id": scene_id, "camera": {"matrix_world": m, "vfov": camera_vfov(cam, scene),
                                             "width": w, "height": h},
            "profile": scene.render_budget.profile or "mobile",
            "fps": scene.render.fps / scene.render.fps_base,
            "format": fmt.lower()}
    if settings is not None:
        body["settings"] = settings
    result = client.render(body, timeout_s=max(client.timeout_s, 120.0))
    directory = Path(bpy.utils.extension_path_user(__package__, path="previews", create=True))
    target = directory / f"preview_{scene.name}_{scene.frame_current}{result.extension}"
    target.write_bytes(result.data)
    old = bpy.data.images.get(IMAGE_NAME)
    if old is not None:
        bpy.data.images.remove(old)
    image = bpy.data.images.load(str(target), check_existing=False)
    image.name = IMAGE_NAME
    image.pack()  # keep the preview in the .blend, independent of the cache folder
    image["render_budget"] = json.dumps({"energy": result.metadata.get("energy"),
                                        "counters": result.metadata.get("counters"),
                                        "settings": settings, "frame": scene.frame_current})
    return image


class RENDER_BUDGET_OT_preview(bpy.types.Operator):
    """Render the current frame with the simulator (active or maximum-quality settings) into an image"""

    bl_idname = "render_budget.preview"
    bl_label = "Preview Frame"

    use_active: bpy.props.BoolProperty(name="Active settings", default=True)  # type: ignore[valid-type]
    format: bpy.props.EnumProperty(  # type: ignore[valid-type]
        name="Format", items=(("PNG", "PNG", "8-bit sRGB"), ("EXR", "EXR", "linear float (OpenEXR)")))
    scale: bpy.props.FloatProperty(name="Scale", default=0.25, min=0.01, max=1.0)  # type: ignore[valid-type]

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            client = service_process.client_for(context)
            image = render_preview(context.scene, client, use_active=self.use_active, fmt=self.format,
                                   scale=self.scale)
        except Exception as err:  # report, never leave a half-made image
            self.report({"ERROR"}, f"Preview failed: {err}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"preview in image {image.name!r} ({image.size[0]}x{image.size[1]})")
        return {"FINISHED"}


class RENDER_BUDGET_OT_analyze_scene(bpy.types.Operator):
    """Upload the scene and list the parameters that cannot change it (greyed out, with the reason)"""

    bl_idname = "render_budget.analyze_scene"
    bl_label = "Analyse Scene"

    def execute(self, context: bpy.types.Context) -> set[str]:
        scene = context.scene
        try:
            check_scene(scene)
            info = upload_scene_info(scene, service_process.client_for(context))
        except Exception as err:  # report to the user; nothing changed
            self.report({"ERROR"}, f"Analyse scene failed: {err}")
            return {"CANCELLED"}
        store = None
        if scene.render_budget.store_text is not None:
            store = pareto_store.ParetoStore.from_json(scene.render_budget.store_text.as_string())
        fill_parameters(scene, info.get("inert_parameters") or {}, store)
        stats = info.get("stats") or {}
        self.report({"INFO"}, f"{stats.get('triangles', '?')} triangles, "
                              f"{len(info.get('inert_parameters') or {})} inert parameters")
        return {"FINISHED"}


classes = (RENDER_BUDGET_OT_preview, RENDER_BUDGET_OT_analyze_scene)
register, unregister = bpy.utils.register_classes_factory(classes)
