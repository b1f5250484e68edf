"""The scene file's constants, reader limits and content type (shared by the writer and the reader)."""

from __future__ import annotations

from dataclasses import dataclass, field

from ...scene_data import SceneData

FORMAT = "render-budget-scene"
VERSION = 1
SUFFIX = ".rbscene"
MEDIA_TYPE = "application/vnd.render-budget.scene+zip"
MANIFEST = "manifest.json"


@dataclass(frozen=True)
class Limits:
    """What a reader accepts (the service passes its own; the defaults suit a desktop job)."""

    max_bytes: int = 2 * 1024**3
    max_triangles: int = 50_000_000
    max_vertices: int = 100_000_000
    max_objects: int = 1_000_000
    max_materials: int = 65_536
    max_environment_texels: int = 64 * 1024 * 1024
    max_texture_texels: int = 256 * 1024 * 1024  # all textures together
    max_textures: int = 4096
    max_manifest_bytes: int = 64 * 1024 * 1024
    max_string: int = 4096
    max_notes: int = 10_000


DEFAULT_LIMITS = Limits()


@dataclass
class SceneFile:
    """A scene file's content: the scene data and the translator's notes (dicts: severity, subject,
    message)."""

    data: SceneData
    notes: list[dict[str, str]] = field(default_factory=list)
    version: int = VERSION


def is_texture_name(name: str) -> bool:
    return name.startswith("texture_") and name[8:].isdigit() and str(int(name[8:])) == name[8:]
