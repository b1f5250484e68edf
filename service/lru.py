"""The one least-recently-used cache of the service (references, scenes, cameras, parsed stores)."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from typing import Generic, TypeVar

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class LRUCache(Generic[K, V]):
    """At most ``capacity`` entries (and, with ``weigh``, at most ``max_weight`` in all, the newest entry
    always kept: e.g. bytes of images whose size varies with the resolution); a hit makes an entry the
    newest, a put beyond the limits drops the oldest. Thread-safe (one lock per cache)."""

    def __init__(self, capacity: int, *, weigh: Callable[[V], int] | None = None,
                 max_weight: int | None = None) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        if (weigh is None) != (max_weight is None):
            raise ValueError("give both weigh and max_weight, or neither")
        self.capacity = capacity
        self.max_weight = max_weight
        self._weigh = weigh
        self.weight = 0
        self._items: OrderedDict[K, V] = OrderedDict()
        self._lock = threading.Lock()

    def _w(self, value: V) -> int:
        return 0 if self._weigh is None else int(self._weigh(value))

    def get(self, key: K) -> V | None:
        with self._lock:
            value = self._items.get(key)
            if value is not None:
                self._items.move_to_end(key)
            return value

    def put(self, key: K, value: V) -> None:
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self.weight -= self._w(old)
            self._items[key] = value
            self.weight += self._w(value)
            while len(self._items) > self.capacity or (
                    self.max_weight is not None and self.weight > self.max_weight and len(self._items) > 1):
                self.weight -= self._w(self._items.popitem(last=False)[1])

    def pop(self, key: K) -> V | None:
        """Forget ``key`` (its value, or None when it was not cached)."""
        with self._lock:
            value = self._items.pop(key, None)
            if value is not None:
                self.weight -= self._w(value)
            return value

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
            self.weight = 0

    def __iter__(self) -> Iterator[K]:
        """The keys, oldest first (a snapshot)."""
        with self._lock:
            return iter(list(self._items))

    def __len__(self) -> int:
        return len(self._items)

    def __contains__(self, key: object) -> bool:
        return key in self._items
