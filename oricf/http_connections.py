"""The connections of every uvicorn server in ORICF (the services' OpenAI-compatible API, the
gateway's control API, MCP over streamable HTTP): a deadline for a request's headers, and
room for a client that asks when the server is full.

uvicorn counts every open connection against `limit_concurrency`, idle ones included, and
answers 503 beyond it; it gives a client unlimited time to send a request's headers. A few
dozen silent sockets (or sockets that dribble a header a minute) would then hold a server
at 503 for as long as they stay open. With `guarded_h11(header_timeout_s)` as uvicorn's
`http` protocol:

- a connection whose request headers are not complete within `header_timeout_s` (counted
  from its opening, or from the end of the previous answer on it) is closed;
- a connection that arrives while the server holds `limit_concurrency` connections closes
  those that have waited longest for a request's headers, as many as it takes for the
  newcomer's request to be served. A connection whose request is in progress, or that is
  closing, is never closed for room, nor one that has waited less than MIN_IDLE_S: in a
  burst of clients, connections are accepted before their requests are read, and closing
  one of them would cut a client off without an answer. When too few connections may go,
  uvicorn's 503 stands.

A server that needs more of its connections (the services close lingering) subclasses
GuardedH11Protocol and passes its class to guarded_h11.
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import ClassVar

from uvicorn.protocols.http.h11_impl import H11Protocol

log = logging.getLogger(__name__)

MIN_IDLE_S = 1.0


class GuardedH11Protocol(H11Protocol):
    """uvicorn's HTTP/1.1 protocol with a header deadline and room for a client that asks;
    made for a server by guarded_h11, which sets the deadline."""

    header_timeout_s: ClassVar[float]
    _header_timer: asyncio.TimerHandle | None = None
    _waiting_since: float | None = None  # monotonic: since when it waits for headers
    _waiting_after: object = None  # the cycle before the request it waits for

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_header_deadline()
        self._make_room()

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        if self.cycle is not self._waiting_after:  # a request's headers are complete
            self._disarm_header_deadline()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():  # a connection that stays waits for its next
            self._arm_header_deadline()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm_header_deadline()
        super().connection_lost(exc)

    def _idle(self) -> bool:
        """Waiting for a request's headers, with no request in progress."""
        in_progress = self.cycle is not None and not self.cycle.response_complete
        return self._waiting_since is not None and not in_progress

    def _make_room(self) -> None:
        limit = self.limit_concurrency
        if limit is None or len(self.connections) < limit:
            return
        now = time.monotonic()
        idle = sorted((c for c in self.connections if c is not self
                       and isinstance(c, GuardedH11Protocol) and c._idle()
                       and now - (c._waiting_since or now) >= MIN_IDLE_S),
                      key=lambda c: c._waiting_since or 0.0)
        # uvicorn serves a request while the connections, its own included, are fewer
        excess = len(self.connections) - limit + 1
        for oldest in idle[:excess]:
            log.debug("%d connections open: closing the one from %s, idle for %.1f s, to "
                      "make room", len(self.connections), oldest.client,
                      now - (oldest._waiting_since or now))
            oldest._close_idle()
        # with too few idle ones (every connection busy or new), uvicorn answers 503

    def _close_idle(self) -> None:
        self._disarm_header_deadline()
        self.connections.discard(self)  # at once: the newcomer's request counts now
        if not self.transport.is_closing():
            self.transport.close()

    def _arm_header_deadline(self) -> None:
        self._disarm_header_deadline()
        self._waiting_after = self.cycle
        self._waiting_since = time.monotonic()
        self._header_timer = self.loop.call_later(self.header_timeout_s,
                                                  self._headers_too_late)

    def _disarm_header_deadline(self) -> None:
        self._waiting_since = None
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def _headers_too_late(self) -> None:
        if self._idle() and not self.transport.is_closing():
            log.debug("closing a connection from %s: no complete request in %g s",
                      self.client, self.header_timeout_s)
            self.transport.close()
        self._waiting_since = None


def guarded_h11(header_timeout_s: float,
                protocol: type[GuardedH11Protocol] = GuardedH11Protocol
                ) -> type[GuardedH11Protocol]:
    """`protocol` (uvicorn's HTTP/1.1 protocol with a header deadline and room for a client
    that asks, or a subclass of it) for a server whose headers must come within
    header_timeout_s."""
    return type(protocol.__name__, (protocol,), {"header_timeout_s": header_timeout_s})
