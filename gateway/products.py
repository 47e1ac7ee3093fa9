"""Data products: the latest value of a named result, its time, and how old it may get.

One route writes a product (`outputs: - {product: people_count, max_age_s: 5}`); others
read it as context for a call, or run on each new value (`input: {product: ...}`). A value
older than max_age_s is stale: readers see that, it is never passed off as current.
As call context a product goes with its age, and stale values are left out or flagged
(methods/generate.py's `fact` turns the readings into oricf.v1.Fact messages).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

Listener = Callable[[Any], None]


@dataclass(frozen=True)
class Reading:
    name: str
    value: Any
    age_s: float
    max_age_s: float

    @property
    def stale(self) -> bool:
        return self.age_s > self.max_age_s


class ProductStore:
    """Thread-safe latest values; `clock` is injectable so staleness is testable."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._max_age: dict[str, float] = {}
        self._latest: dict[str, tuple[Any, float]] = {}
        self._listeners: dict[str, list[Listener]] = {}

    def declare(self, name: str, max_age_s: float) -> None:
        with self._lock:
            self._max_age[name] = max_age_s

    def declared(self) -> list[str]:
        """The names of every declared product."""
        with self._lock:
            return list(self._max_age)

    def subscribe(self, name: str, listener: Listener) -> None:
        """listener(value) is called (in the writer's thread) on every new value."""
        with self._lock:
            self._listeners.setdefault(name, []).append(listener)

    def put(self, name: str, value: Any) -> None:
        with self._lock:
            if name not in self._max_age:
                raise KeyError(f"data product '{name}' was never declared")
            self._latest[name] = (value, self._clock())
            listeners = list(self._listeners.get(name, ()))
        for listener in listeners:
            listener(value)

    def read(self, name: str) -> Reading | None:
        """The latest value with its age, or None if nothing was written yet."""
        with self._lock:
            if name not in self._latest:
                return None
            value, stamp = self._latest[name]
            return Reading(name, value, self._clock() - stamp, self._max_age[name])

    def context(self, names: list[str], stale: Literal["omit", "mark"]) -> list[Reading]:
        """The readings to pass as call context, in the order named: a product never written
        is left out; a stale one is left out (stale="omit") or kept, its `stale` true for the
        receiver to see (stale="mark")."""
        readings = [self.read(name) for name in names]
        return [r for r in readings
                if r is not None and not (r.stale and stale == "omit")]
