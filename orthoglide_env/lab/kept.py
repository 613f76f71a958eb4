"""What a process makes once and keeps, by the arguments that fix it (a design's slot
table, a lab set-up's start-up plan): seconds each to make, so a sweep makes them once
and hands them to its workers, which keep them as if they had made them."""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

Key = TypeVar("Key", bound=Hashable)
Value = TypeVar("Value")


class Kept(Generic[Key, Value]):
    """At most ``size`` values by key, the oldest dropped first."""

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"a store keeps at least one value, got size {size}")
        self.size = size
        self._values: dict[Key, Value] = {}

    def get(self, key: Key, make: Callable[[], Value]) -> Value:
        """The value kept for ``key``; made by ``make`` and kept if there is none."""
        if key not in self._values:
            self._values[key] = make()
            self._trim()
        return self._values[key]

    def made(self) -> dict[Key, Value]:
        """Every value kept, by key: what a sweep's workers are handed (:meth:`handed`)."""
        return dict(self._values)

    def handed(self, values: dict[Key, Value]) -> None:
        """Keep ``values`` (another process's :meth:`made`) as if made here: a key among
        them gets its value without making it; any other is made as before."""
        self._values.update(values)
        self._trim()

    def _trim(self) -> None:
        while len(self._values) > self.size:
            del self._values[next(iter(self._values))]  # the oldest
