"""Add-on preferences: where optimisation jobs run (this computer by default, or a remote service) and
the default hardware profile."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

WHERE = "Preferences > Add-ons > Render Budget"


class RENDER_BUDGET_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    service_mode: EnumProperty(  # type: ignore[valid-type]
        name="Jobs run on",
        items=(
            ("LOCAL", "This computer", "Run optimisation jobs with the simulator bundled in this extension, "
                                       "in a background process started with Blender's Python (no set-up)"),
            ("REMOTE", "Remote service", "Send jobs to a render-budget service (`render-budget serve`) at a "
                                         "URL, with its token"),
        ),
        default="LOCAL",
    )
    url: StringProperty(  # type: ignore[valid-type]
        name="URL", default="", description="The remote service, e.g. http://render-host:8765")
    token: StringProperty(name="Token", subtype="PASSWORD", default="")  # type: ignore[valid-type]
    local_workers: IntProperty(  # type: ignore[valid-type]
        name="Worker processes", default=0, min=0, max=256,
        description="Processes rendering a local job's evaluations (0: one per CPU core)")
    data_dir: StringProperty(  # type: ignore[valid-type]
        name="Data folder",
        description="Local jobs' scenes and evaluation cache (empty: the extension's user folder)",
        subtype="DIR_PATH",
        default="",
    )
    default_profile: StringProperty(name="Default profile", default="mobile")  # type: ignore[valid-type]
    timeout_s: IntProperty(  # type: ignore[valid-type]
        name="Timeout (s)", default=60, min=1, max=3600, description="Remote service requests")
    allow_remote_offline: BoolProperty(  # type: ignore[valid-type]
        name="Ignore 'Allow Online Access' for remote URLs",
        description="Loopback services never need online access; remote ones do unless this is set",
        default=False,
    )

    def draw(self, context: bpy.types.Context) -> None:
        col = self.layout.column()
        col.prop(self, "service_mode", expand=True)
        if self.service_mode == "REMOTE":
            col.prop(self, "url")
            col.prop(self, "token")
            col.prop(self, "timeout_s")
            col.prop(self, "allow_remote_offline")
        else:
            col.prop(self, "local_workers")
            col.prop(self, "data_dir")
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
