"""One worker thread per route, fed through a slot that never lets work pile up.

`latest` (camera routes): one pending item; a newer one replaces it and counts a drop, so
the route always works on the newest frame. `queue` (text, audio): up to queue_size items
in order; when full the oldest is dropped (and counted). Items are loaders (callables that
build the record), so a dropped message is never even converted; an item that is an asker
(oricf.gateway.items) is told why, when the queue drops it and when the worker stops with it
still waiting (a text channel's question, so that its client gets an `error:` line).

A camera route runs its items in its receive thread instead (`handle_here`): there DDS keeps
the newest frame (history depth 1) while the route is busy, so the hand-off to another thread,
and its wake-up, buys nothing. The worker still keeps the route's counts then.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

from oricf.gateway.items import asker_of

log = logging.getLogger(__name__)

T = TypeVar("T")
T_contra = TypeVar("T_contra", contravariant=True)


class Processes(Protocol[T_contra]):
    """What a worker hands its items to: a route (oricf.gateway.route.Route)."""

    def process(self, item: T_contra, /) -> None: ...


@dataclass
class WorkerStats:
    received: int = 0
    dropped: int = 0
    handled: int = 0


class RouteWorker(Generic[T]):
    def __init__(self, name: str, route: Processes[T], mode: str = "latest",
                 queue_size: int = 8) -> None:
        self.name = name
        self.stats = WorkerStats()
        self._route = route
        self._pending: deque[T] = deque(maxlen=1 if mode == "latest" else queue_size)
        self._cond = threading.Condition()
        self._stopping = False
        self._busy = False
        self._thread = threading.Thread(target=self._run, name=f"route-{name}", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def submit(self, item: T) -> None:
        dropped: list[T] = []
        with self._cond:
            self.stats.received += 1
            if len(self._pending) == self._pending.maxlen:
                self.stats.dropped += 1
                dropped.append(self._pending.popleft())
            self._pending.append(item)
            self._cond.notify()
        tell_dropped(dropped, "too many questions waiting; this one was dropped")

    def handle_here(self, item: T, missed: int = 0) -> None:
        """Handles item in the calling thread; `missed` newer-replaced items never arrived."""
        with self._cond:
            self.stats.received += 1 + missed
            self.stats.dropped += missed
            self._busy = True
        self._handle_one(item)
        with self._cond:
            self._busy = False
            self._cond.notify_all()

    def _next(self) -> T | None:
        with self._cond:
            self._busy = False
            self._cond.notify_all()
            while not self._pending and not self._stopping:
                self._cond.wait()
            if self._stopping:
                return None
            self._busy = True
            item = self._pending.popleft()
            self._cond.notify_all()  # room for the next item (wait_room)
            return item

    def _run(self) -> None:
        while (item := self._next()) is not None:
            self._handle_one(item)

    def _handle_one(self, item: T) -> None:
        try:
            self._route.process(item)
        except Exception:  # the route logs its own errors; this is the last guard
            log.exception("route %s: unexpected error", self.name)
        self.stats.handled += 1

    def wait_room(self, timeout: float) -> bool:
        """Waits until an item can be submitted without dropping one (a replay that must
        process every message); False if the timeout came first."""
        with self._cond:
            return self._cond.wait_for(
                lambda: self._stopping or len(self._pending) < (self._pending.maxlen or 1),
                timeout)

    @property
    def depth(self) -> int:
        """Items waiting to be handled."""
        with self._cond:
            return len(self._pending)

    @property
    def busy(self) -> bool:
        """Whether an item is being handled right now."""
        with self._cond:
            return self._busy

    def idle(self, timeout: float) -> bool:
        """Waits until nothing is pending or running (for tests and benchmarks)."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._pending and not self._busy, timeout)

    def clear(self) -> int:
        """Drops what is pending, not the item in progress, without telling anyone (a
        barge-in drops speech nobody waits for); how many were dropped."""
        with self._cond:
            dropped = len(self._pending)
            self.stats.dropped += dropped
            self._pending.clear()
            self._cond.notify_all()
        return dropped

    def stop(self, timeout: float = 5.0) -> None:
        """Drops what is pending, telling each item; lets the item in progress finish
        (bounded by its deadline)."""
        with self._cond:
            self._stopping = True
            dropped = list(self._pending)
            self._pending.clear()
            self._cond.notify_all()
        tell_dropped(dropped, "the gateway is stopping; this question was not answered")
        if self._thread.is_alive():
            self._thread.join(timeout)


def tell_dropped(items: list[T], reason: str) -> None:
    """Outside the worker's lock: telling may take a while."""
    for item in items:
        asker_of(item).on_drop(reason)
