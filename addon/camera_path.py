"""Record camera paths into the .blend: sample the active camera's animation, or record live viewport
navigation into a new keyframed camera (modal, ESC to stop)."""

from __future__ import annotations

import bpy
from mathutils import Matrix

from service import camera_path as path_format
from service.store import camera

from .core.path_sampling import build_path, frame_times

PATH_TEXT_PREFIX = "render_budget_path"


def render_resolution(scene: bpy.types.Scene) -> tuple[int, int]:
    r = scene.render
    scale = r.resolution_percentage / 100.0
    return max(1, round(r.resolution_x * scale)), max(1, round(r.resolution_y * scale))


def camera_vfov(cam_obj: bpy.types.Object, scene: bpy.types.Scene) -> float:
    """Vertical fov (radians) of a perspective camera for the scene's render size."""
    cam = cam_obj.data
    if cam_obj.type != "CAMERA":
        raise ValueError(f"{cam_obj.name!r} is not a camera")
    if cam.type != "PERSP":
        raise ValueError(f"camera {cam_obj.name!r} is {cam.type.lower()}; "
                         "only perspective cameras are supported")
    w, h = render_resolution(scene)
    r = scene.render
    return camera.vertical_fov(cam.angle_x, cam.angle_y, cam.sensor_fit, w, h, r.pixel_aspect_x,
                               r.pixel_aspect_y)


def scene_fps(scene: bpy.types.Scene) -> float:
    return scene.render.fps / scene.render.fps_base


def sample_animation(scene: bpy.types.Scene, cam_obj: bpy.types.Object, step: int = 1
                     ) -> path_format.CameraPath:
    """The camera's evaluated world matrix and fov at every `step`-th frame of the scene's range.

    Uses frame_set, so parent and lens animation, constraints and drivers are all included.
    """
    fps = scene_fps(scene)
    res = render_resolution(scene)
    saved = (scene.frame_current, scene.frame_subframe)
    samples = []
    try:
        for frame, t in frame_times(scene.frame_start, scene.frame_end, fps, step):
            scene.frame_set(frame)
            samples.append((t, [list(row) for row in cam_obj.matrix_world], camera_vfov(cam_obj, scene), res))
    finally:
        scene.frame_set(saved[0], subframe=saved[1])
    return build_path(samples, fps)


def store_path(scene: bpy.types.Scene, path: path_format.CameraPath) -> bpy.types.Text:
    """Keep the path JSON in a text datablock referenced by the scene (saved with the .blend)."""
    props = scene.render_budget
    text = props.path_text
    if text is None:
        text = bpy.data.texts.new(f"{PATH_TEXT_PREFIX}_{scene.name}.json")
        text.use_fake_user = True
        props.path_text = text
    text.from_string(path.to_json())
    return text


def load_path(scene: bpy.types.Scene) -> path_format.CameraPath | None:
    text = scene.render_budget.path_text
    if text is None:
        return None
    return path_format.CameraPath.from_json(text.as_string())


class RENDER_BUDGET_OT_record_path_animation(bpy.types.Operator):
    """Record the camera path from the active camera's animation over the frame range"""

    bl_idname = "render_budget.record_path_animation"
    bl_label = "Record Path from Animation"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    def execute(self, context: bpy.types.Context) -> set[str]:
        scene = context.scene
        cam = scene.camera
        if cam is None:
            self.report({"ERROR"}, "the scene has no active camera")
            return {"CANCELLED"}
        try:
            path = sample_animation(scene, cam, scene.render_budget.frame_step)
        except ValueError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        store_path(scene, path)
        self.report({"INFO"}, f"recorded {len(path)} frames from {cam.name!r}")
        return {"FINISHED"}


def keyframe_pose(cam_obj: bpy.types.Object, frame: int, matrix: Matrix, lens: float) -> None:
    """Keyframe location, rotation (continuous Euler) and lens of `cam_obj` at `frame`."""
    loc, rot, _ = matrix.decompose()
    cam_obj.rotation_mode = "XYZ"
    cam_obj.location = loc
    cam_obj.rotation_euler = rot.to_euler("XYZ", cam_obj.rotation_euler)
    cam_obj.keyframe_insert("location", frame=frame)
    cam_obj.keyframe_insert("rotation_euler", frame=frame)
    cam_obj.data.lens = lens
    cam_obj.data.keyframe_insert("lens", frame=frame)


class RENDER_BUDGET_OT_record_path_viewport(bpy.types.Operator):
    """Record viewport navigation into a new keyframed camera at the scene's frame rate (ESC to stop)"""

    bl_idname = "render_budget.record_path_viewport"
    bl_label = "Record Viewport Navigation"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    _timer = None

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return context.area is not None and context.area.type == "VIEW_3D" and not bpy.app.background

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        scene = context.scene
        cam_data = bpy.data.cameras.new("PowerBudgetRecorded")
        self.cam = bpy.data.objects.new("PowerBudgetRecorded", cam_data)
        scene.collection.objects.link(self.cam)
        self.frame = scene.frame_start
        self.space = context.space_data
        self.region_3d = context.region_data
        wm = context.window_manager
        self._timer = wm.event_timer_add(1.0 / scene_fps(scene), window=context.window)
        wm.modal_handler_add(self)
        context.workspace.status_text_set("Recording camera path: navigate, ESC or right-click to stop")
        return {"RUNNING_MODAL"}

    def _sample(self, context: bpy.types.Context) -> None:
        r3d = self.region_3d
        scene = context.scene
        if r3d.view_perspective == "CAMERA" and scene.camera is not None and scene.camera != self.cam:
            matrix = scene.camera.matrix_world.copy()
            lens = scene.camera.data.lens
        else:
            matrix = r3d.view_matrix.inverted()
            lens = camera.camera_lens_from_viewport(self.space.lens, self.cam.data.sensor_width)
        keyframe_pose(self.cam, self.frame, matrix, lens)
        self.frame += 1

    def _finish(self, context: bpy.types.Context) -> None:
        context.window_manager.event_timer_remove(self._timer)
        self._timer = None
        context.workspace.status_text_set(None)

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if event.type in {"ESC", "RIGHTMOUSE"} and event.value == "PRESS":
            self._finish(context)
            scene = context.scene
            if self.frame == scene.frame_start:
                bpy.data.objects.remove(self.cam)
                self.report({"WARNING"}, "nothing recorded")
                return {"CANCELLED"}
            scene.frame_end = self.frame - 1
            scene.camera = self.cam
            store_path(scene, sample_animation(scene, self.cam, scene.render_budget.frame_step))
            self.report({"INFO"}, f"recorded {self.frame - scene.frame_start} frames into {self.cam.name!r}")
            return {"FINISHED"}
        if event.type == "TIMER" and event.timer == self._timer:
            try:
                self._sample(context)
            except Exception:
                self._finish(context)
                raise
        return {"PASS_THROUGH"}

    def cancel(self, context: bpy.types.Context) -> None:
        if self._timer is not None:
            self._finish(context)


classes = (RENDER_BUDGET_OT_record_path_animation, RENDER_BUDGET_OT_record_path_viewport)
register, unregister = bpy.utils.register_classes_factory(classes)
