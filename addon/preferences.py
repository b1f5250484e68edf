"""Add-on preferences: how to reach the render-budget service, and the default hardware profile."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty


class RENDER_BUDGET_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    service_mode: EnumProperty(  # type: ignore[valid-type]
        name="Service",
        items=(
            ("URL", "Connect to URL", "Use a running render-budget service"),
            ("LOCAL", "Start locally", "Start `render-budget serve` on 127.0.0.1 from a Python environment "
                                       "and stop it when Blender exits"),
        ),
        default="URL",
    )
    url: StringProperty(name="URL", default="http://127.0.0.1:8765")  # type: ignore[valid-type]
    token: StringProperty(name="Token", subtype="PASSWORD", default="")  # type: ignore[valid-type]
    python_path: StringProperty(  # type: ignore[valid-type]
        name="Python",
        description="Python interpreter of an environment where render-budget is installed",
        subtype="FILE_PATH",
        default="",
    )
    local_port: IntProperty(name="Port", default=8765, min=1024, max=65535)  # type: ignore[valid-type]
    data_dir: StringProperty(  # type: ignore[valid-type]
        name="Data folder",
        description="Service data (empty: the extension's user folder)",
        subtype="DIR_PATH",
        default="",
    )
    default_profile: StringProperty(name="Default profile", default="mobile")  # type: ignore[valid-type]
    timeout_s: IntProperty(name="Timeout (s)", default=60, min=1, max=3600)  # type: ignore[valid-type]
    allow_remote_offline: BoolProperty(  # type: ignore[valid-type]
        name="Ignore 'Allow Online Access' for remote URLs",
        description="Loopback services never need online access; remote ones do unless this is set",
        default=False,
    )

    def draw(self, context: bpy.types.Context) -> None:
        col = self.layout.column()
        col.prop(self, "service_mode", expand=True)
        if self.service_mode == "URL":
            col.prop(self, "url")
            col.prop(self, "token")
            col.prop(self, "allow_remote_offline")
        else:
            col.prop(self, "python_path")
            col.prop(self, "local_port")
            col.prop(self, "data_dir")
        col.prop(self, "timeout_s")
        col.prop(self, "default_profile")


def get(context: bpy.types.Context | None = None) -> RENDER_BUDGET_AP_preferences:
    """This add-on's preferences (raises a clear error when the add-on is not enabled as an extension)."""
    ctx = context or bpy.context
    addon = ctx.preferences.addons.get(__package__)
    if addon is None:
        raise RuntimeError(f"add-on {__package__!r} is not enabled")
    return addon.preferences


classes = (RENDER_BUDGET_AP_preferences,)
register, unregister = bpy.utils.register_classes_factory(classes)
