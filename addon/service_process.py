"""Reach the service: a configured URL, or a local `render-budget serve` started on demand and stopped
when the add-on is disabled or Blender exits."""

from __future__ import annotations

import atexit
import os
from pathlib import Path

import bpy

from . import preferences
from .core.client import ServiceClient, is_loopback
from .core.local_service import LocalService

_local: LocalService | None = None


def _data_dir(prefs: preferences.RENDER_BUDGET_AP_preferences) -> Path:
    if prefs.data_dir:
        return Path(bpy.path.abspath(prefs.data_dir))
    return Path(bpy.utils.extension_path_user(__package__, path="service", create=True))


def client_for(context: bpy.types.Context) -> ServiceClient:
    """A client for the configured service, starting the local one if asked to (main thread only)."""
    global _local
    prefs = preferences.get(context)
    if prefs.service_mode == "LOCAL":
        if not prefs.python_path:
            raise RuntimeError("set the Python interpreter of a render-budget environment in the preferences")
        python = bpy.path.abspath(prefs.python_path)
        if _local is None or not _local.running() or _local.port != prefs.local_port:
            stop_local()
            # a desktop service: render a job's evaluations on every core
            _local = LocalService(python, prefs.local_port, _data_dir(prefs), prefs.token or None,
                                  eval_workers=os.cpu_count() or 1)
            _local.start()
        return _local.client(timeout_s=float(prefs.timeout_s))
    # Loopback is not "online": a service on this machine is usable whatever 'Allow Online Access' says.
    if not is_loopback(prefs.url) and not bpy.app.online_access and not prefs.allow_remote_offline:
        raise RuntimeError("a remote service needs 'Allow Online Access' (Preferences > System > Network)")
    return ServiceClient(prefs.url, prefs.token or None, timeout_s=float(prefs.timeout_s))


def stop_local() -> None:
    global _local
    if _local is not None:
        _local.stop()
        _local = None


def local_running() -> bool:
    return _local is not None and _local.running()


class RENDER_BUDGET_OT_service_start(bpy.types.Operator):
    """Start the local render-budget service (or check that the configured URL answers)"""

    bl_idname = "render_budget.service_start"
    bl_label = "Connect to Service"

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            client = client_for(context)
            health = client.health()
        except Exception as err:  # report any failure to the user, nothing else to clean up
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        wm = context.window_manager.render_budget_runtime
        wm.service_status = f"connected: {client.base_url} (version {health.get('version', '?')})"
        profiles = health.get("profiles") or []
        scene_props = context.scene.render_budget
        scene_props.profiles.clear()
        for name in profiles:
            scene_props.profiles.add().name = str(name)
        self.report({"INFO"}, wm.service_status)
        return {"FINISHED"}


class RENDER_BUDGET_OT_service_stop(bpy.types.Operator):
    """Stop the local render-budget service started by this add-on"""

    bl_idname = "render_budget.service_stop"
    bl_label = "Stop Local Service"

    def execute(self, context: bpy.types.Context) -> set[str]:
        stop_local()
        context.window_manager.render_budget_runtime.service_status = "stopped"
        return {"FINISHED"}


classes = (RENDER_BUDGET_OT_service_start, RENDER_BUDGET_OT_service_stop)
_register, _unregister = bpy.utils.register_classes_factory(classes)


def register() -> None:
    _register()
    atexit.register(stop_local)


def unregister() -> None:
    stop_local()
    atexit.unregister(stop_local)
    _unregister()
