"""One generation at a time per model, with a bounded first-come-first-served wait line.

llama.cpp's context is not safe to share between threads, and on a 2-core machine two
interleaved generations would only make both slower. Callers beyond the line's length, or
who wait longer than the timeout, get Overloaded (RESOURCE_EXHAUSTED) so a client can back
off instead of piling up. A waiting caller who goes away leaves the line at once.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from oricf.errors import NotReady, Overloaded

# How often a waiting caller checks whether it is still wanted.
POLL_S = 0.02


class GenerationGate:
    def __init__(self, max_waiting: int, wait_timeout_s: float) -> None:
        self.max_waiting = max_waiting
        self.wait_timeout_s = wait_timeout_s
        self._cond = threading.Condition()
        self._busy = False
        self._closed = False
        self._line: deque[object] = deque()

    @property
    def waiting(self) -> int:
        with self._cond:
            return len(self._line)

    @property
    def busy(self) -> bool:
        with self._cond:
            return self._busy

    @contextmanager
    def turn(self, check: Callable[[], None]) -> Iterator[float]:
        """Holds the model for the block; yields the seconds spent waiting.

        check() is called while waiting and raises when the caller has gone away.
        """
        started = time.perf_counter()
        self._acquire(check)
        try:
            yield time.perf_counter() - started
        finally:
            with self._cond:
                self._busy = False
                self._cond.notify_all()

    def close(self, timeout_s: float) -> bool:
        """Refuses new turns and waits for the running one; False if it is still running."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
            return self._cond.wait_for(lambda: not self._busy, timeout_s)

    def _acquire(self, check: Callable[[], None]) -> None:
        with self._cond:
            self._refuse_if_closed()
            if not self._busy and not self._line:
                self._busy = True
                return
            if len(self._line) >= self.max_waiting:
                raise Overloaded(f"the model is busy and {len(self._line)} request(s) are already "
                                 f"waiting (queue limit {self.max_waiting}); retry later")
            ticket = object()
            self._line.append(ticket)
            try:
                self._wait_for_turn(ticket, check)
            finally:
                self._line.remove(ticket)
                self._cond.notify_all()
            self._busy = True

    def _wait_for_turn(self, ticket: object, check: Callable[[], None]) -> None:
        give_up = time.monotonic() + self.wait_timeout_s
        while self._busy or self._line[0] is not ticket:
            remaining = give_up - time.monotonic()
            if remaining <= 0:
                raise Overloaded(f"waited {self.wait_timeout_s:g} s for the model without a "
                                 f"turn (queue wait timeout); retry later")
            self._cond.wait(min(POLL_S, remaining))
            self._refuse_if_closed()
            check()

    def _refuse_if_closed(self) -> None:
        if self._closed:
            raise NotReady("the language model is shutting down; retry on another instance")
