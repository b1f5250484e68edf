"""What an incremental translation keeps between depsgraph updates, so that an edit in the viewport
re-reads only what it changed (pure: no bpy).

The viewport's depsgraph reports each edit as updates (``is_updated_geometry`` / ``_transform`` /
``_shading`` per ID). Moving an object or the camera changes no mesh: the translator walks the instances
again (their matrices), reuses every extracted mesh and every instance's world-space arrays but the
moved one's, and reuses the materials and the world. A material edit re-reads the materials; a geometry
edit re-extracts the meshes of the objects whose geometry changed. Meshes are keyed by the evaluated
mesh (its address and Blender's session id, which changes whenever the depsgraph evaluates it again),
so linked duplicates and instances share one entry and a freed mesh's address never returns stale
arrays. What an item's reading noted is kept with it and reported again whenever it is reused, so an
incremental translation equals a fresh one, notes included.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from .notes import Note, Notes

T = TypeVar("T")

#: ID types whose update changes what materials read (node trees, images, textures they use).
_MATERIAL_ID_TYPES = frozenset({"MATERIAL", "NODETREE", "IMAGE", "TEXTURE"})
#: ID types whose update changes the world's reading.
_WORLD_ID_TYPES = frozenset({"WORLD", "NODETREE", "IMAGE"})
# ID types whose change never alters what the simulator sees (the scene's own ID changes on every frame
# change; actions change through the transforms they drive, which arrive as object updates).
_IGNORED_ID_TYPES = frozenset({"SCENE", "ACTION", "TEXT", "WINDOWMANAGER", "WORKSPACE", "SCREEN", "BRUSH",
                               "PALETTE", "LINESTYLE"})
#: ID types that change neither materials nor the world (instances and lights are read on every
#: translation anyway; geometry goes by the object's own flag).
_NEUTRAL_ID_TYPES = _IGNORED_ID_TYPES | frozenset({
    "OBJECT", "MESH", "CURVE", "CURVES", "METABALL", "FONT", "LATTICE", "POINTCLOUD", "VOLUME",
    "GREASEPENCIL", "LIGHT", "CAMERA", "COLLECTION", "ARMATURE", "SPEAKER", "LIGHT_PROBE"})


@dataclass(frozen=True)
class Update:
    """One depsgraph update as :func:`needs_translation` and :meth:`TranslationCache.invalidate` read
    it."""

    id_type: str  # ID.id_type: "OBJECT", "MESH", "MATERIAL", ...
    object_type: str = ""  # Object.type for objects: "MESH", "CAMERA", ...
    geometry: bool = False
    transform: bool = False
    shading: bool = False
    name: str = ""  # the original ID's full name


def needs_translation(updates: Iterable[Update]) -> bool:
    """Whether the depsgraph updates change the translated scene. Cameras moving or changing lens do
    not (the camera is read at every draw); everything else that can reach the simulator does."""
    for u in updates:
        if u.id_type in _IGNORED_ID_TYPES or u.id_type == "CAMERA":
            continue
        if u.id_type == "OBJECT" and u.object_type == "CAMERA":
            continue
        if u.id_type == "OBJECT" and not (u.geometry or u.transform or u.shading):
            continue  # selection or other non-evaluated state
        return True
    return False


@dataclass
class Cached(Generic[T]):
    """A value read from Blender and the notes its reading made."""

    value: T
    notes: tuple[Note, ...] = ()

    def replay(self, notes: Notes) -> T:
        for n in self.notes:
            notes.add(n.severity, n.subject, n.message)
        return self.value


@dataclass
class TranslationCache:
    """Everything one viewport keeps between translations (see the module docstring).

    ``meshes``: extracted meshes by evaluated-mesh key; ``materials``: material inputs by material key;
    ``images``: image pixels by image name with their reading's notes (the node-tree reader's table);
    ``world``: (world key, the world's reading); ``transforms``: each instance's world-space arrays by
    (mesh key, matrix bytes).
    ``dirty_objects``: objects (original names) whose geometry changed since the last translation.
    ``extractions`` / ``reuses``: meshes read from Blender / taken from here, over the cache's life.
    """

    meshes: dict[Any, Cached[Any]] = field(default_factory=dict)
    materials: dict[Any, Cached[Any]] = field(default_factory=dict)
    images: dict[str, Any] = field(default_factory=dict)
    world: tuple[Any, Cached[Any]] | None = None
    transforms: dict[Any, Any] = field(default_factory=dict)
    dirty_objects: set[str] = field(default_factory=set)
    extractions: int = 0
    reuses: int = 0

    def invalidate(self, updates: Iterable[Update]) -> None:
        """Forget what ``updates`` (one depsgraph update's list) made stale."""
        for u in updates:
            if u.id_type == "OBJECT" and u.geometry:
                self.dirty_objects.add(u.name)
            if u.id_type == "IMAGE":
                self.images.clear()
            if u.id_type in _MATERIAL_ID_TYPES:
                self.materials.clear()
            if u.id_type in _WORLD_ID_TYPES:
                self.world = None
            if u.id_type not in _MATERIAL_ID_TYPES | _WORLD_ID_TYPES | _NEUTRAL_ID_TYPES:
                # something this translator does not know: materials and world are cheap to read again
                self.materials.clear()
                self.world = None

    def clear(self) -> None:
        """Forget everything (the next translation is a full one)."""
        self.meshes.clear()
        self.materials.clear()
        self.images.clear()
        self.world = None
        self.transforms.clear()
        self.dirty_objects.clear()

    def keep_only(self, mesh_keys: Iterable[Any], material_keys: Iterable[Any]) -> None:
        """After a translation: drop what the scene no longer uses (deleted or hidden objects' meshes), so
        memory follows the scene; the geometry edits are all read now."""
        used = set(mesh_keys)
        self.meshes = {k: v for k, v in self.meshes.items() if k in used}
        used_materials = set(material_keys)
        self.materials = {k: v for k, v in self.materials.items() if k in used_materials}
        self.dirty_objects.clear()
