"""Text channels: a line-based TCP server per entry of the pipeline's `channels:`.

    channels:
      questions: {listen: 127.0.0.1:7000}      # + tls: {cert, key, client_ca}, auth: {file}

A client connects (e.g. `nc 127.0.0.1 7000`, or `openssl s_client` with TLS), sends
questions one per line (UTF-8) and receives the lines routes write to the channel: the
answer to its own question, and lines no question asked for (e.g. a route that announces a
count) go to every client. With `auth`, the first line must be `authorization: Bearer TOKEN`
(compared in constant time, never logged); without it the client gets `error: ...` and is
closed. Too long a line or too many clients: an `error:` line, and nothing else is lost.
"""

from __future__ import annotations

import asyncio
import logging
import ssl
import threading
from collections.abc import Callable

from pydantic import Field, field_validator

from oricf.config import Schema, check_address
from oricf.tls import ServerTls, TokenSource, token_matches

log = logging.getLogger(__name__)


class ChannelConfig(Schema):
    """A line-based text channel on a TCP port: clients send questions as lines and receive
    the outputs written to the channel. TLS (mTLS with client_ca) and bearer tokens as for
    the services; with `auth`, a client's first line is `authorization: Bearer TOKEN`."""

    listen: str = Field(description="host:port; 127.0.0.1 keeps it on this machine")
    tls: ServerTls | None = None
    auth: TokenSource | None = None
    max_clients: int = Field(16, ge=1, le=1024)
    max_line_bytes: int = Field(4096, ge=16, le=1 << 20)

    @field_validator("listen")
    @classmethod
    def _host_port(cls, value: str) -> str:
        return check_address(value)


OnLine = Callable[[str, "Client"], None]
HANDSHAKE_TIMEOUT_S = 10.0
MAX_UNSENT_BYTES = 1 << 20
SHUTDOWN_WAIT_S = 2.0


class Client:
    """One connected client. Its writes happen on the channel's event loop; `send` may be
    called from any thread and never blocks."""

    def __init__(self, writer: asyncio.StreamWriter, loop: asyncio.AbstractEventLoop,
                 peer: str) -> None:
        self.peer = peer
        self.open = True
        self._writer = writer
        self._loop = loop

    def send(self, line: str) -> None:
        if self.open:
            data = (line.replace("\n", " ") + "\n").encode()
            try:
                self._loop.call_soon_threadsafe(self._write, data)
            except RuntimeError:  # the loop has closed
                self.open = False

    def reply(self, line: str) -> None:
        """On the loop itself (the channel's own messages), ahead of anything scheduled."""
        self._write((line + "\n").encode())

    def drop(self) -> None:
        self.open = False
        self._writer.transport.abort()

    def _write(self, data: bytes) -> None:
        # A client that stops reading is closed rather than buffered for without end.
        if self._writer.transport.get_write_buffer_size() > MAX_UNSENT_BYTES:
            log.warning("text channel: %s reads nothing; closing it", self.peer)
            self.drop()
        elif self.open:
            self._writer.write(data)


class TextChannel:
    """One channel's server, on an asyncio loop in a thread of its own."""

    def __init__(self, name: str, config: ChannelConfig) -> None:
        self.name = name
        self.config = config
        self.clients: set[Client] = set()
        self.address = ""
        self._on_line: OnLine | None = None
        self._tokens = [t.encode() for t in config.auth.tokens()] if config.auth else []
        self._tls = self._server_context()
        self._loop = asyncio.new_event_loop()
        self._server: asyncio.Server | None = None
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True,
                                        name=f"channel-{name}")

    def _server_context(self) -> ssl.SSLContext | None:
        tls = self.config.tls
        if tls is None:
            return None
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        context.load_cert_chain(tls.cert, tls.key)
        if tls.client_ca is not None:
            context.verify_mode = ssl.CERT_REQUIRED
            context.load_verify_locations(tls.client_ca)
        return context

    def start(self) -> None:
        """Binds the port (raising OSError if it cannot) and serves clients."""
        host, _, port = self.config.listen.rpartition(":")
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(asyncio.start_server(
            self._serve, host.strip("[]"), int(port), ssl=self._tls,
            limit=self.config.max_line_bytes + 1,
            ssl_handshake_timeout=HANDSHAKE_TIMEOUT_S if self._tls else None), self._loop)
        self._server = future.result(timeout=10)
        host, port = self._server.sockets[0].getsockname()[:2]
        self.address = f"{host}:{port}"
        security = ("TLS" if self._tls else "plaintext") + (", tokens" if self._tokens else "")
        log.info("text channel %s: listening on %s (%s)", self.name, self.address, security)

    def read_by(self, on_line: OnLine) -> None:
        """Lines clients send go to `on_line` (the route that reads this channel)."""
        self._on_line = on_line

    def send(self, line: str, to: Client | None = None) -> None:
        """To the client that asked, while it is connected; else to every client."""
        if to is not None and to.open:
            to.send(line)
            return
        for client in list(self.clients):
            client.send(line)

    def close(self) -> None:
        """Stops listening and drops every client (on the loop: asyncio is not thread-safe)."""
        if not self._thread.is_alive():
            return
        try:
            asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop).result(5)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(5)

    async def _shutdown(self) -> None:
        if self._server is not None:
            self._server.close()
        for client in list(self.clients):
            client.drop()
        # Dropped clients end their own tasks (their reads see the end of the stream).
        # Cancelling those tasks instead would make asyncio's stream protocol log each one
        # as an error; only a task still running after the wait is cancelled.
        tasks = [task for task in asyncio.all_tasks() if task is not asyncio.current_task()]
        _, pending = await asyncio.wait(tasks, timeout=SHUTDOWN_WAIT_S) if tasks else ((), ())
        for task in pending:
            task.cancel()
        await asyncio.gather(*pending, return_exceptions=True)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        host, port = writer.get_extra_info("peername")[:2]
        peer = f"{host}:{port}"
        client = Client(writer, self._loop, peer)
        if len(self.clients) >= self.config.max_clients:
            writer.write(f"error: the channel has {self.config.max_clients} clients "
                         f"already\n".encode())
        else:
            self.clients.add(client)
            log.info("text channel %s: %s connected", self.name, peer)
            try:
                await self._read_lines(reader, client)
            except (OSError, asyncio.IncompleteReadError):
                pass
            finally:
                self.clients.discard(client)
                log.info("text channel %s: %s disconnected", self.name, peer)
        client.open = False
        try:
            writer.close()
            await writer.wait_closed()
        except (OSError, ssl.SSLError):
            pass

    async def _read_lines(self, reader: asyncio.StreamReader, client: Client) -> None:
        authenticated = not self._tokens
        while True:
            try:
                raw = await reader.readuntil(b"\n")
            except asyncio.LimitOverrunError as exc:
                await reader.readexactly(exc.consumed)  # drop what came so far, go on
                client.reply(f"error: a line is at most {self.config.max_line_bytes} bytes")
                await self._skip_line(reader)
                continue
            except asyncio.IncompleteReadError:
                return  # closed (a last line without a newline is not a whole line)
            line = raw.decode("utf-8", "replace").strip()
            if not authenticated:
                if not self._check_token(line):
                    client.reply("error: the first line must be 'authorization: Bearer TOKEN' "
                                 "with a token this channel accepts")
                    return
                authenticated = True
            elif line and self._on_line is not None:
                self._on_line(line, client)

    @staticmethod
    async def _skip_line(reader: asyncio.StreamReader) -> None:
        """Discards up to the end of an over-long line, whatever its length."""
        while True:
            try:
                await reader.readuntil(b"\n")
                return
            except asyncio.LimitOverrunError as exc:
                await reader.readexactly(exc.consumed)

    def _check_token(self, line: str) -> bool:
        key, _, value = line.partition(":")
        scheme, _, token = value.strip().partition(" ")
        return (key.strip().lower() == "authorization" and scheme.lower() == "bearer"
                and token_matches(token.strip(), self._tokens))


class Channels:
    """The pipeline's channels, opened on first use by a source or a sink."""

    def __init__(self, configs: dict[str, ChannelConfig]) -> None:
        self._configs = configs
        self._open: dict[str, TextChannel] = {}
        self._lock = threading.Lock()

    def get(self, name: str) -> TextChannel:
        with self._lock:
            if name not in self._open:
                channel = TextChannel(name, self._configs[name])
                channel.start()
                self._open[name] = channel
            return self._open[name]

    def open_all(self) -> None:
        for name in self._configs:
            self.get(name)

    def close(self) -> None:
        with self._lock:
            for channel in self._open.values():
                channel.close()
            self._open.clear()
