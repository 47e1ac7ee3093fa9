"""Text channels: a line-based TCP server per entry of the pipeline's `channels:`.

    channels:
      questions: {listen: 127.0.0.1:7000}      # + tls: {cert, key, client_ca}, auth: {file}
                                               # (both required beyond loopback)

A client connects (e.g. `nc 127.0.0.1 7000`, or `openssl s_client` with TLS), sends
questions one per line (UTF-8) and receives the lines routes write to the channel: the
answer to its own question, and lines no question asked for (e.g. a route that announces a
count) go to every client. With `auth`, the first line must be `authorization: Bearer TOKEN`
(compared in constant time, never logged); without it the client gets `error: ...` and is
closed. Too long a line or too many clients: an `error:` line, and nothing else is lost.

Connections that have not sent their token wait in a pool of their own (`max_pending`), so
they never take an authenticated client's place, and are closed after `auth_timeout_s`;
clients that send nothing for `idle_timeout_s` are closed too, and one address holds at most
`max_per_address` connections. When a new connection finds its address or its pool full, the
connection there that has sent nothing for longest is closed to make room (`error: closed to
make room ...`): with `auth`, only one yet to send its token; without, one with no question
waiting for its answer. Idle sockets (on a robot every local client shares 127.0.0.1) never
lock a client out. Every question is answered, with the route's answer or an `error:` line
(Client.fail), also when the client half-closes its connection after asking. Lines reach a
client as printable text (clients.one_printable_line).
"""

from __future__ import annotations

import asyncio
import logging
import ssl
import threading
from collections.abc import Callable

from pydantic import Field

from oricf.gateway.channels.clients import Client
from oricf.hosts import Address, ListenAddress
from oricf.tls import ListenerConfig, token_matches

log = logging.getLogger(__name__)


class ChannelConfig(ListenerConfig):
    """A line-based text channel on a TCP port: clients send questions as lines and receive
    the outputs written to the channel. TLS (mTLS with client_ca) and bearer tokens as for
    the services; with `auth`, a client's first line is `authorization: Bearer TOKEN`.
    Beyond loopback, tls and auth are both required (oricf.tls.check_exposure)."""

    listen: ListenAddress = Field(description="host:port; 127.0.0.1 keeps it on this machine "
                                              "(port 0 picks a free one)")
    max_clients: int = Field(16, ge=1, le=1024, description="authenticated clients at once")
    max_pending: int = Field(
        32, ge=1, le=1024, description="connections yet to send their token (with `auth`)")
    max_per_address: int = Field(8, ge=1, le=1024, description="connections from one address")
    auth_timeout_s: float = Field(10.0, gt=0, le=600, description="time to send the token")
    idle_timeout_s: float | None = Field(
        300.0, gt=0, description="a client that sends nothing this long is closed; null: never")
    max_line_bytes: int = Field(4096, ge=16, le=1 << 20)


OnLine = Callable[[str, Client], None]
HANDSHAKE_TIMEOUT_S = 10.0
SHUTDOWN_WAIT_S = 2.0
HALF_CLOSED_WAIT_S = 60.0  # for the answers to a client that half-closed after asking


class TextChannel:
    """One channel's server, on an asyncio loop in a thread of its own."""

    def __init__(self, name: str, config: ChannelConfig) -> None:
        self.name = name
        self.config = config
        self.clients: set[Client] = set()   # authenticated
        self.pending: set[Client] = set()   # yet to send their token
        self._by_address: dict[str, set[Client]] = {}
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
        return tls.ssl_context(f"channels.{self.name}.tls") if tls else None

    def start(self) -> None:
        """Binds the port (raising OSError if it cannot) and serves clients."""
        listen = self.config.listen
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(asyncio.start_server(
            self._serve, listen.host, listen.port, ssl=self._tls,
            limit=self.config.max_line_bytes + 1,
            ssl_handshake_timeout=HANDSHAKE_TIMEOUT_S if self._tls else None), self._loop)
        self._server = future.result(timeout=10)
        self.address = str(Address(*self._server.sockets[0].getsockname()[:2]))
        security = ("TLS" if self._tls else "plaintext") + (", tokens" if self._tokens else "")
        log.info("text channel %s: listening on %s (%s)", self.name, self.address, security)

    def read_by(self, on_line: OnLine) -> None:
        """Lines clients send go to `on_line` (the route that reads this channel)."""
        self._on_line = on_line

    def send(self, line: str, to: Client | None = None) -> None:
        """To the client of this channel that asked (nobody else, even once it has gone);
        else to every client."""
        if to is not None and to.channel == self.name:
            to.send(line, answer=True)
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
        clients = list(self.clients | self.pending)
        for client in clients:
            client.close()  # lines written before (a stopping route's errors) still go out
        # Closed clients end their own tasks (their reads see the end of the stream).
        # Cancelling those tasks instead would make asyncio's stream protocol log each one
        # as an error; only a task still running after the wait is cancelled, and a client
        # that does not read what is left for it is cut off.
        tasks = [task for task in asyncio.all_tasks() if task is not asyncio.current_task()]
        _, pending = await asyncio.wait(tasks, timeout=SHUTDOWN_WAIT_S) if tasks else ((), ())
        for client in clients:
            client.drop()
        for task in pending:
            task.cancel()
        await asyncio.gather(*pending, return_exceptions=True)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        host, port = writer.get_extra_info("peername")[:2]
        client = Client(writer, self._loop, host, port, self.name)
        refusal = self._admit(client, host)
        if refusal:
            client.reply(f"error: {refusal}")
        else:
            log.info("text channel %s: %s connected", self.name, client.peer)
            try:
                await self._read_lines(reader, client)
            except (OSError, asyncio.IncompleteReadError):
                pass
            finally:
                self._forget(client)
                log.info("text channel %s: %s disconnected", self.name, client.peer)
        client.open = False
        try:
            writer.close()
            await writer.wait_closed()
        except (OSError, ssl.SSLError):
            pass

    def _forget(self, client: Client) -> None:
        self.clients.discard(client)
        self.pending.discard(client)
        here = self._by_address.get(client.host)
        if here is not None:
            here.discard(client)
            if not here:  # no entry left behind per address seen
                del self._by_address[client.host]

    def _admit(self, client: Client, host: str) -> str:
        """Takes the client into its pool, closing an idle connection to make room where
        the pool or its address is full; or says why not."""
        here = self._by_address.get(host, set())
        if len(here) >= self.config.max_per_address and not self._make_room(here):
            return f"{host} has {self.config.max_per_address} connections here already"
        pool, size = ((self.pending, self.config.max_pending) if self._tokens else
                      (self.clients, self.config.max_clients))
        if len(pool) >= size and not self._make_room(pool):
            return (f"{size} connections wait to authenticate already" if self._tokens else
                    f"the channel has {size} clients already")
        pool.add(client)
        self._by_address.setdefault(host, set()).add(client)
        return ""

    def _make_room(self, among: set[Client]) -> bool:
        """Closes the connection of `among` that has sent nothing for longest, of those that
        may go; False if none may."""
        movable = [client for client in among if self._movable(client)]
        if not movable:
            return False
        idlest = max(movable, key=lambda client: client.idle_s())
        log.info("text channel %s: closing %s, silent for %.0f s, to make room for a new "
                 "connection", self.name, idlest.peer, idlest.idle_s())
        idlest.reply(f"error: closed to make room for a new connection after "
                     f"{idlest.idle_s():.0f} s without a line")
        self._forget(idlest)
        idlest.close()
        return True

    def _movable(self, client: Client) -> bool:
        """With `auth`, a connection yet to send its token (an authenticated client is never
        closed for room); without, a client with no question waiting for its answer."""
        return client in self.pending if self._tokens else client.answered.is_set()

    def _promote(self, client: Client) -> bool:
        """An authenticated client takes a place among `clients`, if one is free."""
        self.pending.discard(client)
        if len(self.clients) >= self.config.max_clients:
            return False
        self.clients.add(client)
        return True

    async def _read_lines(self, reader: asyncio.StreamReader, client: Client) -> None:
        authenticated = not self._tokens
        while True:
            timeout = self.config.idle_timeout_s if authenticated else self.config.auth_timeout_s
            try:
                line = await asyncio.wait_for(self._next_line(reader, client), timeout)
            except asyncio.TimeoutError:
                client.reply(f"error: nothing came in {timeout:g} s" if authenticated else
                             f"error: no token in {timeout:g} s")
                return
            if line is None:  # the client closed its side: its answers still go to it
                if not client.answered.is_set() and not client.transport_closing():
                    await asyncio.wait_for(client.answered.wait(), HALF_CLOSED_WAIT_S)
                return
            client.heard()
            if not authenticated:
                if not self._check_token(line):
                    client.reply("error: the first line must be 'authorization: Bearer TOKEN' "
                                 "with a token this channel accepts")
                    return
                if not self._promote(client):
                    client.reply(f"error: the channel has {self.config.max_clients} clients "
                                 "already")
                    return
                authenticated = True
            elif line and self._on_line is not None:
                client.asked()
                self._on_line(line, client)

    async def _next_line(self, reader: asyncio.StreamReader, client: Client) -> str | None:
        """The next whole line; None once the client has closed its side."""
        while True:
            try:
                raw = await reader.readuntil(b"\n")
            except asyncio.LimitOverrunError as exc:
                await reader.readexactly(exc.consumed)  # drop what came so far, go on
                client.reply(f"error: a line is at most {self.config.max_line_bytes} bytes")
                await self._skip_line(reader)
                continue
            except asyncio.IncompleteReadError:
                return None  # a last line without a newline is not a whole line
            return raw.decode("utf-8", "replace").strip()

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
