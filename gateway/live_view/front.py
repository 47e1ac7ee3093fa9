"""The live view's listener: what viewers connect to, in front of the foxglove-sdk server.

The SDK's server (0.30) speaks the protocol but has no way to check a token, cap its
clients or the size of what they send, and accepts only the subprotocol `foxglove.sdk.v1`,
which viewers built on the protocol's v1 client (Lichtblick, @foxglove/ws-protocol) do not
offer. So the SDK listens on loopback at a port of its own, and this front, on the
`websockets` library, is the address viewers use: it takes either subprotocol, checks the
bearer token (`Authorization: Bearer TOKEN`, or `?token=TOKEN` for browsers, which cannot
set headers) and TLS (wss://, client certificates with client_ca), refuses viewers beyond
max_clients and messages beyond max_message_bytes, then relays each message unchanged,
but for messages a viewer publishes on a channel of its own: the view takes no data from
viewers (its server offers no client publishing), so those are dropped here and logged as a
warning, at most once per viewer per REFUSAL_LOG_INTERVAL_S with how many came (the SDK
would log each one as an error).
The relay reads from the SDK only as fast as the viewer takes, so a slow viewer's backlog
stays in the SDK's bounded per-client queue, where its oldest frames are dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from http import HTTPStatus
from typing import Any
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.client import connect
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

from oricf.errors import ConfigError
from oricf.gateway.listeners import LiveViewConfig
from oricf.gateway.throttle import ThrottledLog
from oricf.tls import token_matches

log = logging.getLogger(__name__)

SDK_SUBPROTOCOL = Subprotocol("foxglove.sdk.v1")
SUBPROTOCOLS = [SDK_SUBPROTOCOL, Subprotocol("foxglove.websocket.v1")]
HANDSHAKE_TIMEOUT_S = 10.0
PING_INTERVAL_S = 20.0
START_TIMEOUT_S = 10.0
# The wait for the other side's close frame once one side has gone: a viewer that left must
# not hold its place among max_clients for long.
CLOSE_TIMEOUT_S = 1.0
REFUSAL_LOG_INTERVAL_S = 10.0
# From the SDK (trusted, on loopback): a frame of the largest image the gateway takes.
UPSTREAM_MAX_BYTES = 256 << 20
# Bytes written to a viewer before the relay waits for it: a slow viewer stalls only its own
# relay, and the SDK drops that viewer's oldest frames.
WRITE_LIMIT_BYTES = 256 << 10
# Messages the relay reads ahead from the SDK for a viewer before it stops reading.
RELAY_QUEUE = 4
# The binary op of Client Message Data: a message on a channel the viewer advertised.
CLIENT_MESSAGE_DATA = 0x01


class Front:
    def __init__(self, config: LiveViewConfig, sdk_port: int) -> None:
        self.config = config
        self.host, self.port = config.listen.host, config.listen.port
        self._sdk_url = f"ws://127.0.0.1:{sdk_port}"
        self._tokens = [t.encode() for t in config.auth.tokens()] if config.auth else []
        self._ssl = config.tls.ssl_context("foxglove.tls") if config.tls else None
        self._viewers: set[ServerConnection] = set()
        self._refusals = ThrottledLog(log, REFUSAL_LOG_INTERVAL_S)  # a flood logs a line
        # The library logs each request line and header at DEBUG, a token with them: its
        # log for the front stops at INFO whatever the process's level.
        self._library_log = logging.getLogger(f"{__name__}.connections")
        self._library_log.setLevel(logging.INFO)
        self._loop = asyncio.new_event_loop()
        self._server: Server | None = None
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True,
                                        name="live-view-front")

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'wss' if self._ssl else 'ws'}://{host}:{self.port}"

    @property
    def viewers(self) -> int:
        return len(self._viewers)

    def start(self) -> None:
        self._thread.start()
        opened = asyncio.run_coroutine_threadsafe(self._open(), self._loop)
        try:
            opened.result(START_TIMEOUT_S)
        except OSError as exc:
            self._stop_loop()
            raise ConfigError(f"foxglove: cannot listen on {self.config.listen}: "
                              f"{exc.strerror or exc}") from None

    async def _open(self) -> None:
        self._server = await serve(
            self._relay, self.host, self.port, ssl=self._ssl, subprotocols=SUBPROTOCOLS,
            process_request=self._admit, max_size=self.config.max_message_bytes,
            max_queue=4, write_limit=WRITE_LIMIT_BYTES, open_timeout=HANDSHAKE_TIMEOUT_S,
            ping_interval=PING_INTERVAL_S, ping_timeout=PING_INTERVAL_S,
            close_timeout=CLOSE_TIMEOUT_S, server_header=None, logger=self._library_log,
            # asyncio's own TLS handshake deadline (60 s) cut to the WebSocket one
            ssl_handshake_timeout=HANDSHAKE_TIMEOUT_S if self._ssl else None)
        self.port = self._server.sockets[0].getsockname()[1]

    def _admit(self, connection: ServerConnection, request: Request) -> Response | None:
        """Refuses before the upgrade: a wrong or missing token, one viewer too many."""
        if self._tokens and not token_matches(_token(request), self._tokens):
            self._refusals.warning("token", "live view: %s refused: no valid token",
                                   _peer(connection))
            return connection.respond(HTTPStatus.UNAUTHORIZED, "a valid token is needed\n")
        if len(self._viewers) >= self.config.max_clients:
            self._refusals.warning("full", "live view: %s refused: %d viewers already",
                                   _peer(connection), len(self._viewers))
            return connection.respond(HTTPStatus.SERVICE_UNAVAILABLE, "too many viewers\n")
        return None

    async def _relay(self, viewer: ServerConnection) -> None:
        if viewer.subprotocol is None:
            await viewer.close(1002, f"offer a subprotocol: {', '.join(SUBPROTOCOLS)}")
            return
        self._viewers.add(viewer)
        log.info("live view: viewer %s connected (%d now)", _peer(viewer), len(self._viewers))
        try:
            async with connect(self._sdk_url, subprotocols=[SDK_SUBPROTOCOL],
                               max_size=UPSTREAM_MAX_BYTES, max_queue=RELAY_QUEUE,
                               ping_interval=None, close_timeout=CLOSE_TIMEOUT_S) as sdk:
                await _first_to_end(_from_viewer(viewer, sdk), _pipe(sdk, viewer))
        except (OSError, ConnectionClosed) as exc:
            log.warning("live view: relay for %s ended: %s", _peer(viewer), exc)
        finally:
            self._viewers.discard(viewer)
            log.info("live view: viewer %s left (%d now)", _peer(viewer), len(self._viewers))

    def close(self) -> None:
        if self._server is not None:
            server = self._server

            async def shut() -> None:
                server.close()
                await server.wait_closed()

            with contextlib.suppress(Exception):
                asyncio.run_coroutine_threadsafe(shut(), self._loop).result(START_TIMEOUT_S)
        self._stop_loop()

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)


async def _pipe(source: Any, sink: Any) -> None:
    with contextlib.suppress(ConnectionClosed):
        async for message in source:
            await sink.send(message)


class UnacceptedMessages:
    """A viewer's messages on channels of its own, for the log: the first at once, then at
    most one line per interval with how many came since, and the rest when it leaves."""

    def __init__(self, peer: str, interval_s: float = REFUSAL_LOG_INTERVAL_S) -> None:
        self.peer = peer
        self.interval_s = interval_s
        self.total = 0
        self._unlogged = 0
        self._latest = "?"
        self._logged_at: float | None = None

    def add(self, message: bytes) -> None:
        self.total += 1
        self._unlogged += 1
        self._latest = str(int.from_bytes(message[1:5], "little")) if len(message) >= 5 \
            else "?"
        now = time.monotonic()
        if self._logged_at is None or now - self._logged_at >= self.interval_s:
            self._log()
            self._logged_at = now

    def _log(self) -> None:
        log.warning("live view: viewer %s sent %d message(s) on channels of its own (the "
                    "latest on channel %s); dropped: the view takes no data from viewers",
                    self.peer, self._unlogged, self._latest)
        self._unlogged = 0

    def close(self) -> None:
        if self._unlogged:
            self._log()


async def _from_viewer(viewer: ServerConnection, sdk: Any) -> None:
    """What the viewer sends, to the SDK, less its messages on channels of its own."""
    unaccepted = UnacceptedMessages(_peer(viewer))
    try:
        with contextlib.suppress(ConnectionClosed):
            async for message in viewer:
                if isinstance(message, bytes) and message[:1] == bytes([CLIENT_MESSAGE_DATA]):
                    unaccepted.add(message)
                    continue
                await sdk.send(message)
    finally:
        unaccepted.close()


async def _first_to_end(*pipes: Any) -> None:
    """Runs both directions until either ends (a side closed), then stops the other."""
    tasks = [asyncio.ensure_future(p) for p in pipes]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


def _token(request: Request) -> str:
    header = request.headers.get("Authorization", "")
    scheme, _, token = header.partition(" ")
    if scheme.lower() == "bearer" and token:
        return token.strip()
    return (parse_qs(urlsplit(request.path).query).get("token") or [""])[0]


def _peer(connection: ServerConnection) -> str:
    address = connection.remote_address
    return f"{address[0]}:{address[1]}" if address else "?"
