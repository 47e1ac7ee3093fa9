"""The per-service call limit and memory budget: calls beyond them are refused at once,
with pushback.

A refusal is RESOURCE_EXHAUSTED carrying `grpc-retry-pushback-ms` (the trailing metadata key
gRPC's own retry policy honours) and the same hint in its message, so clients wait before
trying again instead of hammering a busy service. Health checks and reflection are exempt:
an orchestrator must see a busy service as alive.
"""

from __future__ import annotations

import random
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from oricf.errors import InvalidInput, Overloaded

PUSHBACK_KEY = "grpc-retry-pushback-ms"
EXEMPT_PREFIXES = ("/grpc.health.v1.", "/grpc.reflection.")
# Exempt calls that stream requests (reflection's ServerReflectionInfo) open at once: each
# holds a thread while it waits for the client, so they are bounded on their own. grpcurl
# opens one per command and closes it when done.
EXEMPT_STREAMS = 4


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


class MemoryBudget:
    """The bytes of decoded images and input tensors that calls may hold at once.

    The call limit alone does not bound memory: a few hundred bytes of JPEG can claim tens
    of megapixels, and a tensor's shape decides how much a network allocates. Each call
    holds its estimate (made before anything is decoded) until it ends; one that does not
    fit beside the others is refused at once with pushback, as a call over the limit is.
    """

    def __init__(self, limit_bytes: int, retry_after_ms: int) -> None:
        self.limit_bytes = limit_bytes
        self.retry_after_ms = retry_after_ms
        self._held = 0
        self._lock = threading.Lock()

    @contextmanager
    def hold(self, nbytes: int, what: str) -> Iterator[None]:
        """Holds nbytes for the block; InvalidInput for more than the whole budget (it could
        never run here), Overloaded when the others leave too little."""
        mb = nbytes / 2**20
        if nbytes > self.limit_bytes:
            raise InvalidInput(f"{what}: about {mb:,.0f} MB to hold while it runs, more than "
                               f"the service's whole budget for data in flight "
                               f"({self.limit_mb:,.0f} MB)")
        with self._lock:
            fits = self._held + nbytes <= self.limit_bytes
            if fits:
                self._held += nbytes
        if not fits:
            wait_ms = pushback_ms(self.retry_after_ms)
            raise Overloaded(f"the service is busy: {what}: about {mb:,.0f} MB to hold while "
                             f"it runs, and calls in progress hold most of its "
                             f"{self.limit_mb:,.0f} MB for data in flight; retry in {wait_ms} ms",
                             wait_ms)
        try:
            yield
        finally:
            with self._lock:
                self._held -= nbytes

    @property
    def held(self) -> int:
        """Bytes held by calls in progress."""
        with self._lock:
            return self._held

    @property
    def limit_mb(self) -> float:
        return self.limit_bytes / 2**20
