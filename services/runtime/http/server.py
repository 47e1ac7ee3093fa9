"""uvicorn in a thread of the service process: its own socket, TLS, limits and a clean stop.

The socket is bound when the server is made, so a port in use fails the service at start
like the gRPC port does, and port 0 is known before anything is served. uvicorn cuts off
idle keep-alive connections and refuses requests beyond `max_connections` with 503; the
connection rules every uvicorn server in ORICF shares (oricf.http_connections) close a
connection whose headers are not complete within `request_timeout_s` (a slowloris client
that dribbles a header a minute would otherwise hold its connection for ever) and, at a
full server, close the connections idle longest so that a client that asks is served
(silent sockets would otherwise hold the API at 503). The body's deadline is kept by the
app (guards.py).

A connection closed while its client is still sending a body (an answer of 413 or 408, or
any refusal before the body was read) is closed lingering, as web servers do: the answer's
side is ended first, and what the client goes on sending is read and dropped for at most
LINGER_S or LINGER_BYTES before the socket closes. Closing a socket with unread bytes at
once resets the connection, and a client still writing its body would see the reset instead
of the answer.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import ssl
import threading
from typing import Any

import h11
import uvicorn

from oricf.errors import ConfigError
from oricf.hosts import Address
from oricf.http_connections import GuardedH11Protocol, guarded_h11
from oricf.services.runtime.config import HttpSettings
from oricf.tls import ServerTls

log = logging.getLogger(__name__)

# How long starting may take before the service gives up (binding is already done).
START_TIMEOUT_S = 10.0
# After the grace period, how long uvicorn may take to cancel what is left.
STOP_MARGIN_S = 5.0
# A lingering close reads and drops the rest of a refused body for at most this long, and
# this much.
LINGER_S = 2.0
LINGER_BYTES = 64 * 1024 * 1024


class LingeringClose:
    """A connection's transport whose close(), while the client is still sending its body,
    ends the answer's side (when the transport can: not under TLS) and keeps reading for
    the protocol to drop, until the client closes, LINGER_S pass or LINGER_BYTES arrive."""

    def __init__(self, transport: asyncio.Transport, still_sending: Any,
                 loop: asyncio.AbstractEventLoop) -> None:
        self._transport = transport
        self._still_sending = still_sending
        self._loop = loop
        self._timer: asyncio.TimerHandle | None = None
        self.lingering = False
        self.dropped = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._transport, name)

    def is_closing(self) -> bool:
        return self.lingering or self._transport.is_closing()

    def close(self) -> None:
        if self.lingering or self._transport.is_closing() or not self._still_sending():
            self.close_now()
            return
        self.lingering = True
        if self._transport.can_write_eof():
            self._transport.write_eof()  # after what is still buffered: the answer
        self._transport.resume_reading()
        self._timer = self._loop.call_later(LINGER_S, self.close_now)

    def close_now(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._transport.close()

    def drop(self, data: bytes) -> None:
        """Bytes that arrived while lingering: dropped, the connection closed at the cap."""
        self.dropped += len(data)
        if self.dropped > LINGER_BYTES:
            self.close_now()


class LingeringH11Protocol(GuardedH11Protocol):
    """The shared HTTP/1.1 protocol, closing lingering while a client is still sending a
    body."""

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        self._lingering = LingeringClose(transport, self._still_sending, self.loop)
        super().connection_made(self._lingering)  # type: ignore[arg-type]

    def _still_sending(self) -> bool:
        return self.conn.their_state is h11.SEND_BODY

    def data_received(self, data: bytes) -> None:
        if self._lingering.lingering:
            self._lingering.drop(data)
            return
        super().data_received(data)

    def eof_received(self) -> None:
        if self._lingering.lingering:  # the client has read the answer and left
            self._lingering.close_now()

    def connection_lost(self, exc: Exception | None) -> None:
        self._lingering.close_now()
        super().connection_lost(exc)


def _bind(listen: str) -> socket.socket:
    address = Address.parse(listen, any_port=True)
    host, port = address.host, address.port
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ConfigError(f"server.http: cannot listen on {listen}: "
                          f"{exc.strerror or exc}") from None
    sock.listen(128)
    sock.setblocking(False)
    return sock


class HttpServer:
    """Serves an ASGI app on `settings.listen` from a thread, until stop()."""

    def __init__(self, app: Any, settings: HttpSettings, tls: ServerTls | None,
                 grace_s: float, name: str) -> None:
        self._socket = _bind(settings.listen)
        self.port: int = self._socket.getsockname()[1]
        self.name = name
        self.scheme = "https" if tls else "http"
        context = tls.ssl_context("server.tls") if tls else None
        config = uvicorn.Config(
            app, http=guarded_h11(settings.request_timeout_s, LingeringH11Protocol),
            lifespan="off", ws="none",
            log_config=None, access_log=False, server_header=False, proxy_headers=False,
            limit_concurrency=settings.max_connections,
            timeout_keep_alive=settings.keep_alive_s,  # type: ignore[arg-type]
            timeout_graceful_shutdown=grace_s,  # type: ignore[arg-type]
            ssl_context_factory=_fixed(context) if context else None,
            # uvicorn needs a certificate file name to switch TLS on at all
            ssl_certfile=str(tls.cert) if tls else None)
        self._server = uvicorn.Server(config)
        # uvicorn's start and stop lines repeat the service's own; its warnings stay.
        logging.getLogger("uvicorn.error").setLevel(logging.WARNING)
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"{name}-http")

    def _run(self) -> None:
        try:
            self._server.run(sockets=[self._socket])
        except BaseException:  # a dying server thread must say why
            log.exception("%s: the HTTP server stopped", self.name)

    def start(self) -> None:
        self._thread.start()
        waited = 0.0
        while not self._server.started and self._thread.is_alive() and waited < START_TIMEOUT_S:
            threading.Event().wait(0.02)
            waited += 0.02
        if not self._server.started:
            raise ConfigError(f"{self.name}: the HTTP server did not start")

    def stop(self, grace_s: float) -> bool:
        """Stops accepting, lets requests in flight finish within grace_s; False if the
        server thread was still running after that and the margin."""
        self._server.should_exit = True
        self._thread.join(grace_s + STOP_MARGIN_S)
        if self._thread.is_alive():
            self._server.force_exit = True
            return False
        return True


def _fixed(context: ssl.SSLContext) -> Any:
    return lambda config, default: context
