"""The per-service call limit: calls beyond it are refused at once, with pushback.

A refusal is RESOURCE_EXHAUSTED carrying `grpc-retry-pushback-ms` (the trailing metadata key
gRPC's own retry policy honours) and the same hint in its message, so clients wait before
trying again instead of hammering a busy service. Health checks and reflection are exempt:
an orchestrator must see a busy service as alive.
"""

from __future__ import annotations

import random
import threading

PUSHBACK_KEY = "grpc-retry-pushback-ms"
EXEMPT_PREFIXES = ("/grpc.health.v1.", "/grpc.reflection.")


class CallLimit:
    def __init__(self, limit: int, retry_after_ms: int) -> None:
        self.limit = limit
        self.retry_after_ms = retry_after_ms
        self._active = 0
        self._lock = threading.Lock()

    def try_enter(self) -> bool:
        with self._lock:
            if self._active >= self.limit:
                return False
            self._active += 1
            return True

    def leave(self) -> None:
        with self._lock:
            self._active -= 1

    @property
    def active(self) -> int:
        """Calls admitted and not yet finished."""
        with self._lock:
            return self._active

    def pushback_ms(self) -> int:
        return pushback_ms(self.retry_after_ms)


def pushback_ms(retry_after_ms: int) -> int:
    """The suggested wait, with jitter so refused clients do not return in step."""
    return int(retry_after_ms * random.uniform(1.0, 2.0))


def exempt(method: str) -> bool:
    return method.startswith(EXEMPT_PREFIXES)
