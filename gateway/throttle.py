"""Throttled logging: a failing service or a bad publisher must not flood the log."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable


class Throttle:
    """Per key: the first event at once, then at most one per interval_s, counting the
    rest. With max_keys, once that many keys are held, those quiet for an interval are
    forgotten (a key chosen by a client, such as its address, cannot grow it without end)."""

    def __init__(self, interval_s: float, clock: Callable[[], float] = time.monotonic,
                 max_keys: int | None = None) -> None:
        self.interval_s = interval_s
        self._clock = clock
        self._max_keys = max_keys
        self._lock = threading.Lock()
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def admit(self, key: str) -> int | None:
        """None to suppress this one; else how many of the key's were suppressed before."""
        now = self._clock()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self.interval_s:
                self._suppressed[key] = self._suppressed.get(key, 0) + 1
                return None
            if self._max_keys is not None and len(self._last) >= self._max_keys:
                self._forget_quiet(now)
            self._last[key] = now
            return self._suppressed.pop(key, 0)

    def _forget_quiet(self, now: float) -> None:
        for key, last in list(self._last.items()):
            if now - last >= self.interval_s:
                del self._last[key]
                self._suppressed.pop(key, None)


class ThrottledLog:
    """Logs the first message of each key at once, then at most one per interval_s,
    saying how many were suppressed in between."""

    def __init__(self, logger: logging.Logger, interval_s: float = 10.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._logger = logger
        self._throttle = Throttle(interval_s, clock)

    def log(self, level: int, key: str, message: str, *args: object) -> bool:
        """Returns whether the message was written."""
        suppressed = self._throttle.admit(key)
        if suppressed is None:
            return False
        if suppressed:
            message += (f" ({suppressed} similar suppressed in the last "
                        f"{self._throttle.interval_s:g} s)")
        self._logger.log(level, message, *args)
        return True

    def warning(self, key: str, message: str, *args: object) -> bool:
        return self.log(logging.WARNING, key, message, *args)

    def error(self, key: str, message: str, *args: object) -> bool:
        return self.log(logging.ERROR, key, message, *args)
