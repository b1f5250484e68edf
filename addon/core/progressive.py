"""Progressive rendering on a worker thread, coarse to fine, restarted whenever what is shown changes.
Pure (no bpy): the render engine's viewport calls :meth:`ProgressiveDriver.update` from ``view_draw`` and
draws :meth:`ProgressiveDriver.latest`; tests drive it without a GPU.

A request is rendered at a few sizes, smallest first (``scales`` of the request's size), each published
as soon as it is done. A new request (a different ``key``) restarts: a refinement level in flight is
cancelled at its next band, but a request's first (coarsest) level always completes, so that a stream
of requests (playback, an object being dragged) still shows a new image per coarse render instead of
cancelling every one; requests that arrive meanwhile are skipped, the newest wins. ``close()`` cancels
everything and ends the thread.

:func:`workers_paused` holds every driver's worker still (the level in flight cancelled at its next
band, then re-rendered afterwards) for main-thread work during which no other Python thread may run:
Blender's render operator, which the scene translation for a job uses.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from .engine_frame import RenderCancelled

#: The render function: (payload, width, height, should_stop) -> (RGBA image (h, w, 4), info).
RenderFn = Callable[[Any, int, int, Callable[[], bool]], tuple[np.ndarray, Any]]


@dataclass(frozen=True)
class ViewRequest:
    """What to show: ``key`` identifies the image (equal keys: nothing to redo), ``payload`` is what
    the render function needs, at ``width`` x ``height`` pixels for the finest level."""

    key: Hashable
    width: int
    height: int
    payload: Any = None

    def __post_init__(self) -> None:
        if not (isinstance(self.width, int) and isinstance(self.height, int) and self.width > 0
                and self.height > 0):
            raise ValueError(f"view size must be positive integers, got {self.width}x{self.height}")


@dataclass(frozen=True)
class ViewFrame:
    """One published image: request ``serial`` (1, 2, ... in update order) at refinement ``level``."""

    image: np.ndarray
    serial: int
    key: Hashable
    level: int
    levels: int
    info: Any

    @property
    def final(self) -> bool:
        return self.level == self.levels - 1


_drivers: weakref.WeakSet[ProgressiveDriver] = weakref.WeakSet()
_pause_lock = threading.Lock()
_pauses = 0  # nesting depth of workers_paused()


def _paused() -> bool:
    return _pauses > 0


@contextmanager
def workers_paused(timeout: float = 10.0) -> Iterator[None]:
    """While the block runs, no driver's worker runs Python: each stops its render at the next band and
    waits (in a lock, the GIL released) until the block ends, then renders its request again. Raises
    TimeoutError (and resumes them) if a worker is still busy after ``timeout`` seconds."""
    global _pauses
    with _pause_lock:
        _pauses += 1
    try:
        deadline = time.monotonic() + timeout
        for driver in list(_drivers):
            if not driver.wait_parked(max(0.0, deadline - time.monotonic())):
                raise TimeoutError("a viewport render did not stop in time; try again")
        yield
    finally:
        with _pause_lock:
            _pauses -= 1
        for driver in list(_drivers):
            driver.wake()


class ProgressiveDriver:
    """One worker thread rendering the newest request coarse to fine (see the module docstring)."""

    def __init__(self, render: RenderFn, scales: tuple[float, ...] = (0.25, 0.5, 1.0),
                 on_frame: Callable[[ViewFrame], None] | None = None) -> None:
        if not scales or any(not 0.0 < s <= 1.0 for s in scales) or list(scales) != sorted(scales):
            raise ValueError(f"scales must be increasing fractions in (0, 1], got {scales}")
        self._render = render
        self.scales = tuple(float(s) for s in scales)
        self._on_frame = on_frame
        self._cond = threading.Condition()
        self._pending: tuple[int, ViewRequest] | None = None
        self._active: tuple[int, ViewRequest] | None = None
        self._latest: ViewFrame | None = None
        self._key: Hashable = None
        self._serial = 0
        self._closed = False
        self.error: str | None = None  # the last render failure (cleared by the next success)
        self.frames = 0  # images published
        self.cancelled = 0  # levels stopped before they finished
        self._thread = threading.Thread(target=self._run, name="render-budget-viewport", daemon=True)
        _drivers.add(self)
        self._thread.start()

    # -- caller side ---------------------------------------------------------------------------------
    def update(self, request: ViewRequest) -> bool:
        """Show ``request``; returns whether that restarts rendering (its key differs from the last)."""
        with self._cond:
            if self._closed:
                raise RuntimeError("the progressive driver is closed")
            if request.key == self._key:
                return False
            self._serial += 1
            self._key = request.key
            self._pending = (self._serial, request)
            self._cond.notify_all()
            return True

    def latest(self) -> ViewFrame | None:
        with self._cond:
            return self._latest

    @property
    def busy(self) -> bool:
        with self._cond:
            return self._pending is not None or self._active is not None

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until every request is rendered (True) or the timeout passes (False)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._pending is not None or self._active is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return True

    def close(self, wait: bool = True, timeout: float = 10.0) -> None:
        """Cancel what is in flight and end the worker (what the engine does when it is freed); the
        worker stops at its next band (``wait``: block until it has)."""
        with self._cond:
            self._closed = True
            self._pending = None
            self._cond.notify_all()
        if wait and threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def wait_parked(self, timeout: float) -> bool:
        """Under :func:`workers_paused`: block until the worker is out of any render (True), or the
        timeout passes (False)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._active is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return True

    def wake(self) -> None:
        with self._cond:
            self._cond.notify_all()

    # -- worker side ---------------------------------------------------------------------------------
    def _run(self) -> None:
        while True:
            with self._cond:
                while (self._pending is None or _paused()) and not self._closed:
                    self._cond.wait(0.5 if _paused() else None)  # woken by wake(); the timeout a safety net
                if self._closed:
                    self._active = None
                    self._cond.notify_all()
                    return
                self._active, self._pending = self._pending, None
            serial, request = self._active
            try:
                self._render_levels(serial, request)
            finally:
                with self._cond:
                    self._active = None
                    self._cond.notify_all()

    def _stop_level(self, level: int) -> bool:
        # Read without the lock: a stale answer only delays the stop by one band.
        return self._closed or _paused() or (level > 0 and self._pending is not None)

    def _requeue_if_paused(self, serial: int, request: ViewRequest) -> None:
        """A render stopped by workers_paused() starts again afterwards (unless a newer one waits)."""
        if _paused():
            with self._cond:
                if self._pending is None and not self._closed:
                    self._pending = (serial, request)

    def _render_levels(self, serial: int, request: ViewRequest) -> None:
        levels = len(self.scales)
        for level, scale in enumerate(self.scales):
            if self._stop_level(level):
                self.cancelled += 1
                self._requeue_if_paused(serial, request)
                return
            w = max(1, round(request.width * scale))
            h = max(1, round(request.height * scale))
            try:
                image, info = self._render(request.payload, w, h, lambda lv=level: self._stop_level(lv))
            except RenderCancelled:
                self.cancelled += 1
                self._requeue_if_paused(serial, request)
                return
            except Exception as exc:  # shown by the engine; the worker keeps serving new requests
                self.error = f"{type(exc).__name__}: {exc}"
                return
            frame = ViewFrame(np.asarray(image), serial, request.key, level, levels, info)
            with self._cond:
                if self._closed:
                    return
                self._latest = frame
                self.frames += 1
                self.error = None
            if self._on_frame is not None:
                self._on_frame(frame)
