"""Text channels against clients that hold on or leave early, on real sockets on localhost:
idle connections never lock authenticated clients out (a pool of their own, timeouts, a bound
per address), and every question is answered (an `error:` line for one the route's queue
dropped), also for a client that half-closed its connection after asking, and only to the
client that asked."""

from __future__ import annotations

import socket
import ssl
import struct
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import pytest

from oricf.gateway.channels.server import ChannelConfig, Channels, Client, TextChannel
from oricf.gateway.config import InputConfig
from oricf.gateway.sources.text import Question, TextSource
from oricf.gateway.worker import RouteWorker
from oricf.launch.health import free_port
from tests.support.certs import TOKEN as SECRET

TOKEN = f"authorization: Bearer {SECRET}\n".encode()


def open_channel(config: dict[str, Any], answer_after_s: float = 0.0) -> TextChannel:
    """A channel whose route answers each line with `got LINE`, from another thread."""
    channel = TextChannel("questions", ChannelConfig.model_validate(
        {"listen": f"127.0.0.1:{free_port()}", **config}))
    channel.start()

    def echo(line: str, client: Client) -> None:
        threading.Timer(answer_after_s, channel.send, (f"got {line}", client)).start()

    channel.read_by(echo)
    return channel


def secure(certs: Path, **config: Any) -> dict[str, Any]:
    return {"tls": {"cert": certs / "server.pem", "key": certs / "server.key"},
            "auth": {"file": certs / "tokens"}, **config}


def connect(channel: TextChannel, certs: Path | None = None) -> socket.socket:
    host, port = channel.address.rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=10)
    if certs is None:
        return sock
    context = ssl.create_default_context(cafile=str(certs / "ca.pem"))
    return context.wrap_socket(sock, server_hostname="localhost")


def line_of(sock: socket.socket) -> str:
    return sock.makefile("r", encoding="utf-8").readline()


@pytest.fixture
def channels() -> Iterator[list[TextChannel]]:
    opened: list[TextChannel] = []
    yield opened
    for channel in opened:
        channel.close()


def settle(channel: TextChannel, connected: int) -> None:
    deadline = time.monotonic() + 2
    while len(channel.clients) + len(channel.pending) < connected and \
            time.monotonic() < deadline:
        time.sleep(0.02)


def test_idle_connections_never_take_an_authenticated_clients_place(
        certs: Path, channels: list[TextChannel]) -> None:
    channel = open_channel(secure(certs, max_clients=2, auth_timeout_s=30))
    channels.append(channel)
    with ExitStack() as stack:
        for _ in range(4):  # TLS done, then nothing: more than max_clients
            stack.enter_context(connect(channel, certs))
        settle(channel, 4)
        with connect(channel, certs) as sock:
            sock.sendall(TOKEN + b"ping\n")
            assert line_of(sock) == "got ping\n"


@pytest.mark.parametrize(("config", "first_line", "told"), [
    ({"auth_timeout_s": 0.5}, b"", "error: no token in 0.5 s\n"),
    ({"idle_timeout_s": 0.5}, TOKEN, "error: nothing came in 0.5 s\n"),
])
def test_a_client_that_sends_nothing_is_told_and_closed(
        certs: Path, channels: list[TextChannel], config: dict[str, Any], first_line: bytes,
        told: str) -> None:
    channel = open_channel(secure(certs, **config))
    channels.append(channel)
    with connect(channel, certs) as sock:
        sock.sendall(first_line)
        lines = sock.makefile("r", encoding="utf-8")
        assert lines.readline() == told
        assert lines.readline() == ""  # closed


def test_connections_beyond_a_bound_are_told(certs: Path, channels: list[TextChannel]) -> None:
    """An address whose connections are all authenticated clients: none is closed for room."""
    channel = open_channel(secure(certs, max_per_address=3))
    channels.append(channel)
    with ExitStack() as stack:
        for n in range(3):
            sock = stack.enter_context(connect(channel, certs))
            sock.sendall(TOKEN + f"ping {n}\n".encode())
            assert line_of(sock) == f"got ping {n}\n"
        with connect(channel, certs) as sock:
            assert line_of(sock) == "error: 127.0.0.1 has 3 connections here already\n"


@pytest.mark.parametrize("config", [{"max_per_address": 3}, {"max_pending": 3}])
def test_a_full_pool_closes_its_idlest_connection_for_a_new_one(
        certs: Path, channels: list[TextChannel], config: dict[str, Any]) -> None:
    channel = open_channel(secure(certs, auth_timeout_s=300, **config))
    channels.append(channel)
    with ExitStack() as stack:
        idle = [stack.enter_context(connect(channel, certs)) for _ in range(3)]
        settle(channel, 3)
        with connect(channel, certs) as sock:
            sock.sendall(TOKEN + b"ping\n")
            assert line_of(sock) == "got ping\n"
        oldest = idle[0].makefile("r", encoding="utf-8")
        assert oldest.readline().startswith("error: closed to make room for a new connection")
        assert oldest.readline() == ""  # closed


@pytest.mark.parametrize("config", [{}, {"auth_timeout_s": 300}])
def test_idle_clients_of_one_address_never_lock_a_client_out(
        certs: Path, channels: list[TextChannel], config: dict[str, Any]) -> None:
    """Eight idle connections from 127.0.0.1 (the bound per address; on a robot every local
    client has that address) on a channel without tokens and on one with: a client that
    asks is answered at once, and an idle one makes room."""
    secured = certs if config else None
    channel = open_channel(secure(certs, **config) if config else {})
    channels.append(channel)
    with ExitStack() as stack:
        idle = [stack.enter_context(connect(channel, secured)) for _ in range(8)]
        settle(channel, 8)
        for n in range(3):  # each one stays: the next finds the address full again
            sock = stack.enter_context(connect(channel, secured))
            sock.sendall((TOKEN if config else b"") + f"ping {n}\n".encode())
            assert line_of(sock) == f"got ping {n}\n"
        for sock in idle[:3]:  # the three idlest made room, one for each client
            assert line_of(sock).startswith("error: closed to make room")


def test_a_client_waiting_for_its_answer_is_never_closed_for_room(
        channels: list[TextChannel]) -> None:
    channel = open_channel({"max_per_address": 2}, answer_after_s=1.0)
    channels.append(channel)
    with connect(channel) as asker, connect(channel) as idle:
        asker.sendall(b"slow question\n")
        wait_until(lambda: any(not c.answered.is_set() for c in channel.clients))
        with connect(channel) as newcomer:
            newcomer.sendall(b"ping\n")
            assert line_of(newcomer) == "got ping\n"
        assert line_of(asker) == "got slow question\n"
        assert line_of(idle).startswith("error: closed to make room")


def test_control_characters_reach_a_client_escaped(channels: list[TextChannel]) -> None:
    """ESC, NUL, BEL, the C1 set and DEL as `\\xNN`, line breaks as spaces, tab kept: a
    display's terminal is never driven by what a route or an agent writes."""
    channel = open_channel({})
    channels.append(channel)
    with connect(channel) as display:
        display.sendall(b"hello\n")  # answered: the display is a client of the channel now
        assert line_of(display) == "got hello\n"
        channel.send("\x1b[2J\x1b]0;title\x07a\x00b\tc\rd\x85e\u2028f\x9b1m\x7f")
        assert line_of(display) == \
            "\\x1b[2J\\x1b]0;title\\x07a\\x00b\tc d e f\\x9b1m\\x7f\n"


def test_a_client_that_half_closes_after_asking_gets_its_answer(
        channels: list[TextChannel]) -> None:
    channel = open_channel({}, answer_after_s=0.5)
    channels.append(channel)
    with connect(channel) as sock:
        sock.sendall(b"hello\n")
        sock.shutdown(socket.SHUT_WR)  # as `nc -N` does at the end of its input
        lines = sock.makefile("r", encoding="utf-8")
        assert lines.readline() == "got hello\n"
        assert lines.readline() == ""  # then the channel closes


def test_the_answer_to_a_client_that_left_goes_to_nobody_else(
        channels: list[TextChannel]) -> None:
    channel = open_channel({}, answer_after_s=0.5)
    channels.append(channel)
    with connect(channel) as other:
        with connect(channel) as asker:
            asker.sendall(b"my secret question\n")
            time.sleep(0.1)  # the line reached the channel
            asker.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            # closed with a reset: gone for good, not merely done sending
        time.sleep(1)  # the answer came meanwhile
        channel.send("for everyone")  # a line no question asked for
        assert line_of(other) == "for everyone\n"


class Answers:
    """A route that answers `answered LINE` on its channel once released."""

    def __init__(self, channel: TextChannel) -> None:
        self.channel = channel
        self.release = threading.Event()

    def process(self, load: Question) -> None:
        record = load()
        self.release.wait(10)
        self.channel.send(f"answered {record['text']}", record["reply_to"])


@contextmanager
def busy_route(queue_size: int) -> Iterator[tuple[TextChannel, RouteWorker[Question],
                                                 threading.Event]]:
    """A channel whose questions go to a route that answers `answered LINE` once released,
    one at a time, from a queue of queue_size: the channel, the route's worker, the release."""
    channel = open_channel({})
    route = Answers(channel)
    worker: RouteWorker[Question] = RouteWorker("ask", route, "queue", queue_size=queue_size)
    worker.start()
    TextSource("ask", InputConfig(text="questions"), worker.submit, lambda r: None,
               FixedChannels(channel)).start()
    try:
        yield channel, worker, route.release
    finally:
        route.release.set()
        worker.stop()
        channel.close()


def wait_until(condition: Callable[[], bool], timeout: float = 10) -> None:
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)


def test_a_question_the_routes_queue_drops_is_told_so() -> None:
    """The route is busy and its queue holds two questions: the oldest waiting ones are
    dropped as more come, and their client hears of it."""
    with busy_route(queue_size=2) as (channel, worker, release), connect(channel) as sock:
        lines = sock.makefile("r", encoding="utf-8")
        sock.sendall(b"q0\n")
        wait_until(lambda: worker.busy)
        sock.sendall(b"q1\nq2\nq3\nq4\n")  # q0 runs; q1 and q2 give way to q3 and q4
        told = [lines.readline() for _ in range(2)]
        release.set()
        answers = [lines.readline() for _ in range(3)]
    assert told == ["error: too many questions waiting; this one was dropped\n"] * 2
    assert answers == ["answered q0\n", "answered q3\n", "answered q4\n"]


def test_questions_waiting_when_the_gateway_stops_are_told_so() -> None:
    """The route is busy with one question and two wait: stopping the gateway (its workers,
    then its channels) answers the waiting two with an error line, the one in progress with
    its answer, and only then closes the connection."""
    with busy_route(queue_size=4) as (channel, worker, release), connect(channel) as sock:
        lines = sock.makefile("r", encoding="utf-8")
        sock.sendall(b"q0\n")
        wait_until(lambda: worker.busy)
        sock.sendall(b"q1\nq2\n")
        wait_until(lambda: worker.depth == 2)
        worker.stop(timeout=0.1)  # as the gateway stops: q0 is still running
        release.set()
        assert worker.idle(10)
        channel.close()
        received = lines.readlines()  # to the end: the channel closed the connection
    assert received == ["error: the gateway is stopping; this question was not answered\n"] * 2 \
        + ["answered q0\n"]


class FixedChannels(Channels):
    """The pipeline's channels, here the one channel the test opened."""

    def __init__(self, channel: TextChannel) -> None:
        super().__init__({})
        self._open[channel.name] = channel
