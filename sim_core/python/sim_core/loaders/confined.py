"""Files a scene file refers to (glTF buffers and images, OBJ material libraries, an environment map) are
read only from the scene file's own folder: the reference is resolved (``..`` and symbolic links
included) and must stay inside it, so a scene cannot make its reader open anything else."""

from __future__ import annotations

from pathlib import Path


def shown(reference: str) -> str:
    """A reference as the scene file wrote it, shortened for messages (never resolved, never read)."""
    return repr(reference if len(reference) <= 80 else reference[:77] + "...")


def confined_path(folder: Path, reference: str) -> Path:
    """``folder / reference`` resolved; ValueError if that leaves ``folder`` (nothing is opened)."""
    base = folder.resolve()
    target = (base / reference).resolve()  # follows symbolic links: where the bytes really are
    if not target.is_relative_to(base):
        raise ValueError(f"{shown(reference)} points outside the scene's folder")
    return target
