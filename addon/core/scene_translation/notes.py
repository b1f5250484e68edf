"""What the translation could not carry exactly, in words for the artist (:class:`Note`), and the
translator's result (:class:`Translation`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    from sim_core.scene_data import SceneData

Severity = Literal["info", "warning"]


@dataclass(frozen=True)
class Note:
    """Something the simulated scene does differently from Blender's render, in words for the artist."""

    severity: Severity
    subject: str  # what it is about: "material 'Glass'", "light 'Area'", "world", "object 'Cube'"
    message: str

    def __str__(self) -> str:
        return f"{self.subject}: {self.message}"

    def to_dict(self) -> dict[str, str]:
        return {"severity": self.severity, "subject": self.subject, "message": self.message}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Note:
        sev = str(d.get("severity", "info"))
        if sev not in ("info", "warning"):
            raise ValueError(f"note severity must be 'info' or 'warning', got {sev!r}")
        return cls(sev, str(d.get("subject", "")), str(d.get("message", "")))  # type: ignore[arg-type]


class Notes:
    """An ordered set of notes: the same remark about the same thing is kept once."""

    def __init__(self) -> None:
        self._items: dict[tuple[str, str, str], Note] = {}

    def add(self, severity: Severity, subject: str, message: str) -> None:
        note = Note(severity, subject, message)
        self._items.setdefault((note.severity, note.subject, note.message), note)

    def info(self, subject: str, message: str) -> None:
        self.add("info", subject, message)

    def warn(self, subject: str, message: str) -> None:
        self.add("warning", subject, message)

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self._items.values())

    def __len__(self) -> int:
        return len(self._items)

    def as_list(self) -> list[Note]:
        return list(self._items.values())


def notes_text(notes: Sequence[Note], limit: int = 8) -> str:
    """A short multi-line summary for a panel or a job status (warnings first)."""
    ordered = sorted(notes, key=lambda n: n.severity != "warning")
    lines = [str(n) for n in ordered[:limit]]
    if len(ordered) > limit:
        lines.append(f"... and {len(ordered) - limit} more")
    return "\n".join(lines)


@dataclass
class Translation:
    """The translator's result: scene data ready for ``sim_core.Scene.from_scene_data`` plus notes.

    ``stats``: counts of what was read (objects, instances, unique meshes, triangles, lights, ...) and
    ``seconds`` spent; ``frame`` the scene frame the depsgraph was evaluated at. ``pass_indices``: each
    object's (instance's) Object Index pass value, indexed like ``scene_data.object_names``.
    """

    scene_data: SceneData
    notes: list[Note] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)
    pass_indices: list[int] = field(default_factory=list)  # Blender's Object Index, by object id

    @property
    def warnings(self) -> list[Note]:
        return [n for n in self.notes if n.severity == "warning"]

    def notes_text(self, limit: int = 8) -> str:
        return notes_text(self.notes, limit)
