"""Files saved before a rename keep their settings: on load, an old ``Scene.power_budget`` group (now
unregistered, so Blender keeps it as raw ID properties) is copied into ``Scene.render_budget`` once and
then removed, and settings saved under an older property name (:data:`RENAMED`) move to the new one."""

from __future__ import annotations

import logging

import bpy
from bpy.app.handlers import persistent

from .handlers import add_handler, remove_handler

log = logging.getLogger(__name__)

LEGACY_GROUP = "power_budget"
#: Older property name -> (current name, the old enum's identifiers in item order, or None).
RENAMED: dict[str, tuple[str, tuple[str, ...] | None]] = {
    "threshold_power": ("threshold_power_w", None),
    "camera_sampling": ("view_sampling", ("path", "aimed", "axis")),  # was PATH / AIMED / AXIS
}


def _renamed(values: dict) -> dict:
    """Raw ID-property values under their current names (old enum values as the new identifiers)."""
    out = {}
    for key, value in values.items():
        new, items = RENAMED.get(key, (key, None))
        if items is not None:
            value = items[value] if isinstance(value, int) else str(value).lower()
        out.setdefault(new, value)
    return out


def migrate_renamed(group: bpy.types.PropertyGroup) -> None:
    """Move values saved under an older property name of the current group to the new name."""
    old = {key: group[key] for key in RENAMED if key in group.keys()}
    if not old:
        return
    skipped = _assign(group, _renamed(old))
    for key in old:
        del group[key]
    if skipped:
        log.warning("render-budget: settings not carried over from older names: %s", ", ".join(skipped))


def _assign(target: bpy.types.bpy_struct, values: dict) -> list[str]:
    """Copy raw ID-property values onto a registered property group; returns the keys it could not use."""
    skipped = []
    for key, value in values.items():
        prop = target.bl_rna.properties.get(key)
        if prop is None or (prop.is_readonly and prop.type != "COLLECTION"):
            skipped.append(key)
            continue
        try:
            if prop.type == "COLLECTION":
                items = getattr(target, key)
                items.clear()
                for entry in value:
                    item = items.add()
                    skipped += [f"{key}.{k}" for k in _assign(item, _as_dict(entry))]
            elif prop.type == "ENUM":
                # ID properties store an enum as its item's value (the item's index here).
                names = [item.identifier for item in prop.enum_items]
                setattr(target, key, names[value] if isinstance(value, int) else value)
            elif prop.type == "POINTER":
                if isinstance(value, bpy.types.ID):
                    setattr(target, key, value)
                else:
                    skipped.append(key)
            else:
                setattr(target, key, value)
        except (TypeError, ValueError, IndexError, AttributeError):
            skipped.append(key)
    return skipped


def _as_dict(group: object) -> dict:
    to_dict = getattr(group, "to_dict", None)
    return to_dict() if to_dict is not None else dict(group)  # type: ignore[call-overload]


def migrate_scene(scene: bpy.types.Scene) -> bool:
    """Move the legacy group of one scene into the current one; True when there was one."""
    migrate_renamed(scene.render_budget)
    if LEGACY_GROUP not in scene.keys():
        return False
    legacy = scene[LEGACY_GROUP]
    # ID pointers (the path and store texts) survive only when read item by item, not through to_dict().
    values = {key: legacy[key] for key in legacy.keys()}
    values = {k: (_as_list(v) if k in ("parameters", "profiles") else v) for k, v in values.items()}
    skipped = _assign(scene.render_budget, _renamed(values))
    del scene[LEGACY_GROUP]
    if skipped:
        log.warning("render-budget: scene %r: settings not carried over from the old format: %s",
                    scene.name, ", ".join(sorted(skipped)))
    return True


def _as_list(value: object) -> list[dict]:
    return [_as_dict(entry) for entry in value]  # type: ignore[attr-defined]


@persistent
def on_load(*_args: object) -> None:
    for scene in bpy.data.scenes:
        migrate_scene(scene)


def register() -> None:
    add_handler(bpy.app.handlers.load_post, on_load)
    on_load()  # the file open when the extension is enabled


def unregister() -> None:
    remove_handler(bpy.app.handlers.load_post, on_load)
