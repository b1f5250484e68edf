"""Where jobs run: on this computer with the bundled core (the default: scenes analysed in this process,
each optimisation job in a child process started with Blender's own Python), or on a remote service at a
URL. Local jobs end with their job, when the add-on is disabled, when Blender exits and when Blender is
killed (`core.local_jobs`)."""

from __future__ import annotations

import atexit
import os
from pathlib import Path

import bpy

from . import preferences
from .core.client import ServiceClient, ServiceUnavailable, is_loopback, normalise_base_url
from .core.local_jobs import LocalClient

_local: LocalClient | None = None


def local_data_dir(prefs: preferences.RENDER_BUDGET_AP_preferences) -> Path:
    if prefs.data_dir:
        return Path(bpy.path.abspath(prefs.data_dir))
    return Path(bpy.utils.extension_path_user(__package__, path="local", create=True))


def local_client(context: bpy.types.Context) -> LocalClient:
    """The local client for the current preferences (kept while jobs run; main thread only)."""
    global _local
    prefs = preferences.get(context)
    data_dir = local_data_dir(prefs)
    workers = prefs.local_workers or os.cpu_count() or 1
    if _local is None or ((_local.data_dir, _local.workers) != (data_dir, workers) and not _local.job_pids()):
        stop_local()
        _local = LocalClient(data_dir, workers=workers)
    return _local


def remote_client(prefs: preferences.RENDER_BUDGET_AP_preferences) -> ServiceClient:
    """A client for the remote service in the preferences; errors say what to set up."""
    url = prefs.url.strip()
    if not url:
        raise RuntimeError(f"no remote service URL is set: enter it in {preferences.WHERE} "
                           "(e.g. http://render-host:8765), or choose 'This computer' to run jobs here")
    try:
        base = normalise_base_url(url)
    except ValueError:
        raise RuntimeError(f"the remote service URL {url!r} is malformed: it must look like "
                           f"http://host:port or https://host:port ({preferences.WHERE})") from None
    # Loopback is not "online": a service on this machine is usable whatever 'Allow Online Access' says.
    if not is_loopback(base) and not bpy.app.online_access and not prefs.allow_remote_offline:
        raise RuntimeError(f"the remote service {base} needs 'Allow Online Access' (Preferences > System > "
                           f"Network), or choose 'This computer' in {preferences.WHERE}")
    return ServiceClient(base, prefs.token or None, timeout_s=float(prefs.timeout_s))


def client_for(context: bpy.types.Context) -> ServiceClient | LocalClient:
    """The client the operators use: local by default, the remote service if chosen (main thread only)."""
    prefs = preferences.get(context)
    if prefs.service_mode == "REMOTE":
        return remote_client(prefs)
    return local_client(context)


def explain(err: BaseException) -> str:
    """An error message for the user that says what to set up when the remote service is unreachable."""
    if isinstance(err, ServiceUnavailable):
        return (f"{err}: start it there (`render-budget serve`), correct the URL in {preferences.WHERE}, "
                "or choose 'This computer' to run jobs here")
    return str(err)


def stop_local() -> None:
    """Stop every local job still running (the add-on is disabled or Blender exits)."""
    global _local
    if _local is not None:
        _local.close()
        _local = None


def local_job_pids() -> list[int]:
    return _local.job_pids() if _local is not None else []


class RENDER_BUDGET_OT_service_start(bpy.types.Operator):
    """Check where jobs run: the bundled simulator on this computer, or that the remote service answers"""

    bl_idname = "render_budget.service_start"
    bl_label = "Check Jobs Backend"

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            client = client_for(context)
            health = client.health()
        except Exception as err:  # report any failure to the user, nothing else to clean up
            self.report({"ERROR"}, explain(err))
            context.window_manager.render_budget_runtime.service_status = f"error: {explain(err)}"
            return {"CANCELLED"}
        wm = context.window_manager.render_budget_runtime
        if isinstance(client, LocalClient):
            wm.service_status = (f"this computer: bundled simulator {health.get('version', '?')}, "
                                 f"{health.get('workers')} worker processes")
        else:
            wm.service_status = f"remote: {client.base_url} (version {health.get('version', '?')})"
        profiles = health.get("profiles") or []
        scene_props = context.scene.render_budget
        scene_props.profiles.clear()
        for name in profiles:
            scene_props.profiles.add().name = str(name)
        self.report({"INFO"}, wm.service_status)
        return {"FINISHED"}


classes = (RENDER_BUDGET_OT_service_start,)
_register, _unregister = bpy.utils.register_classes_factory(classes)


def register() -> None:
    _register()
    atexit.register(stop_local)


def unregister() -> None:
    stop_local()
    atexit.unregister(stop_local)
    _unregister()
