"""The render engine's scene between frames: when to translate Blender's scene again, and the built
simulator scene (its BVH) kept while the translated scene is unchanged. Pure (no bpy).

Two signals, because Blender gives two: the viewport's ``view_update`` sees incremental depsgraph
updates (:func:`needs_translation` decides from them whether the scene must be translated again; a
camera moving, as in playback of a camera animation, needs nothing), while a final render gets a fresh
depsgraph per frame in which everything reads as updated, so there the scene is translated every frame
and :class:`SceneCache` keeps the built scene while the translation's content is the same.
"""

from __future__ import annotations

import dataclasses
import hashlib
import threading
from typing import Any

import numpy as np

import sim_core

from .scene_translation.cache import Update, needs_translation

__all__ = ["NOT_RENDERED", "SceneCache", "Update", "fingerprint", "needs_translation"]


def _feed(h: Any, value: Any) -> None:
    """Hash every byte of a scene description: arrays by content, dataclasses field by field."""
    if isinstance(value, np.ndarray):
        arr = np.ascontiguousarray(value)
        h.update(f"nd{arr.dtype.str}{arr.shape}".encode())
        h.update(arr.tobytes())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        h.update(type(value).__name__.encode())
        for f in dataclasses.fields(value):
            h.update(f.name.encode())
            _feed(h, getattr(value, f.name))
    elif isinstance(value, list | tuple):
        h.update(f"seq{len(value)}".encode())
        for v in value:
            _feed(h, v)
    elif isinstance(value, dict):
        h.update(f"map{len(value)}".encode())
        for k in sorted(value, key=repr):
            _feed(h, k)
            _feed(h, value[k])
    else:
        h.update(f"{type(value).__name__}:{value!r};".encode())


#: SceneData fields that do not change what the engine renders: the cameras a scene file carries (the
#: engine renders Blender's camera) and where the data came from.
NOT_RENDERED = frozenset({"cameras", "source"})


def fingerprint(scene_data: Any) -> str:
    """Content hash of what a translated scene renders (``sim_core.SceneData``: every field but
    :data:`NOT_RENDERED`; any dataclass of arrays, dataclasses, sequences and plain values)."""
    h = hashlib.blake2b(digest_size=20)
    if dataclasses.is_dataclass(scene_data) and not isinstance(scene_data, type):
        for f in dataclasses.fields(scene_data):
            if f.name not in NOT_RENDERED:
                h.update(f.name.encode())
                _feed(h, getattr(scene_data, f.name))
    else:
        _feed(h, scene_data)
    return h.hexdigest()


class SceneCache:
    """The last built ``sim_core.Scene``, reused while the translated scene's content is the same.

    Thread-safe: the viewport builds on its worker thread, final renders on the main thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._key: str | None = None
        self._scene: Any = None
        self.builds = 0

    def scene_for(self, scene_data: Any, key: str | None = None) -> Any:
        """The built scene of ``scene_data`` (``key``: its fingerprint, when the caller has it)."""
        key = key or fingerprint(scene_data)
        with self._lock:
            if key == self._key:
                return self._scene
            scene = sim_core.Scene.from_scene_data(scene_data)
            self._key, self._scene = key, scene
            self.builds += 1
            return scene

    def clear(self) -> None:
        with self._lock:
            self._key, self._scene = None, None
