"""Where a store's figures were measured, said beside every figure the product shows.

A store priced at display resolution holds its error, power and frame-time figures for that display only:
the same settings at the path's own (larger) size draw more power and show more error. A store made
without display pricing holds the search's preview figures (errors of a small render, power scaled from
it by the pixel count), which are never the result. So the lookup's callers (REST, the add-on's panel and
HUD, the render engine) label each figure with :meth:`FiguresSize.label` or :meth:`FiguresSize.short`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from .camera import check_resolution

Size = tuple[int, int]


@dataclass(frozen=True)
class FiguresSize:
    """How a store's figures were measured: ``display`` (renders at ``resolution``, the display the store
    was priced for), ``preview`` (the search's renders at ``resolution``, power scaled by the pixel count)
    or ``unknown`` (a store that does not say; ``resolution`` None)."""

    kind: Literal["display", "preview", "unknown"]
    resolution: Size | None

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any]) -> FiguresSize:
        """Read from a store's ``meta`` (``figures_resolution`` and ``display_pricing``, written since
        display pricing; older stores: their ``eval_resolution``, which were all preview figures).
        ValueError for a size that is not two positive integers."""
        figures = meta.get("figures_resolution")
        if figures is not None:
            size = _size(figures, "figures_resolution")
            preview = meta.get("display_pricing", "preview") == "preview"
            return cls("preview" if preview else "display", size)
        if meta.get("eval_resolution") is not None:
            return cls("preview", _size(meta["eval_resolution"], "eval_resolution"))
        return cls("unknown", None)

    def fields(self) -> dict[str, Any]:
        """``figures_resolution`` ([w, h] or None) and ``figures_kind``: how answers (REST, the CLI's JSON)
        carry it."""
        return {"figures_resolution": list(self.resolution) if self.resolution else None,
                "figures_kind": self.kind}

    @property
    def display(self) -> Size | None:
        """The display size the figures hold for (None: preview or unknown figures)."""
        return self.resolution if self.kind == "display" else None

    def label(self, render: Size | None = None) -> str:
        """What the figures are, as words to follow "figures" (``render``: the size the user renders at,
        named when it is not the size the figures hold for)."""
        if self.kind == "unknown":
            return "of a size the store does not record"
        w, h = self.resolution  # type: ignore[misc]
        if self.kind == "preview":
            return f"from {w}x{h} preview renders, power scaled by the pixel count"
        text = f"for a {w}x{h} display"
        if render is not None and tuple(render) != self.resolution:
            text += f", not this scene's {render[0]}x{render[1]}"
        return text

    def short(self, render: Size | None = None) -> str:
        """A few characters for the HUD and the render engine: ``640x360`` (``640x360, not 1280x720``
        beside a ``render`` of another size), ``preview 64x36`` or ``size unknown``."""
        if self.kind == "unknown":
            return "size unknown"
        w, h = self.resolution  # type: ignore[misc]
        if self.kind == "preview":
            return f"preview {w}x{h}"
        if render is not None and tuple(render) != self.resolution:
            return f"{w}x{h}, not {render[0]}x{render[1]}"
        return f"{w}x{h}"


def _size(value: Any, name: str) -> Size:
    if not isinstance(value, (list, tuple)) or len(value) != 2 or any(isinstance(v, bool) for v in value):
        raise ValueError(f"store meta {name} must be [width, height], got {value!r}")
    try:
        return check_resolution(*value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ValueError(f"store meta {name}: {exc}") from exc
