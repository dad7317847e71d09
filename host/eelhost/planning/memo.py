"""A small, thread-safe, least-recently-used cache of values that are costly to build.

The planners of one world share what does not depend on the water they swim in: the clearance
field and the seeded draws of the water (docs/planning.md, "The replan's deadline"). Both are
kept here, built outside the lock (two threads may build the same value; either is kept).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

V = TypeVar("V")


class BoundedCache(Generic[V]):
    """The ``size`` most recently used values, by key.

    Parameters
    ----------
    size : int
        Values kept; the least recently used goes first.
    """

    def __init__(self, size: int) -> None:
        self.size = int(size)
        self._values: OrderedDict[Hashable, V] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: Hashable, build: Callable[[], V]) -> V:
        """The value kept under ``key``, else ``build()``'s, kept.

        Parameters
        ----------
        key : hashable
        build : callable
            Builds the value; called outside the lock.

        Returns
        -------
        value
        """
        with self._lock:
            if key in self._values:
                self._values.move_to_end(key)
                return self._values[key]
        value = build()
        with self._lock:
            self._values[key] = value
            while len(self._values) > self.size:
                self._values.popitem(last=False)
        return value
