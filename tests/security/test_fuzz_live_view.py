"""Hostile viewers of the live view (oricf.gateway.live_view) over real sockets, while a
feeder keeps showing frames with detections: any text or binary WebSocket message (unknown
ops, wrong types, bogus channel ids, messages on channels the viewer never advertised,
invalid JSON and UTF-8), raw bytes instead of a handshake, requests without or with unknown
subprotocols, messages over the size limit, one viewer too many, connections that never
finish their handshake. Whatever comes, the
offending connection is refused or closed, showing never blocks, a viewer's mistake is
never logged as an error, and the next viewer is served."""

from __future__ import annotations

import json
import logging
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, suppress

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from oricf.gateway.listeners import LiveViewConfig
from oricf.gateway.live_view import front
from oricf.gateway.live_view.view import LiveView
from oricf.gateway.values import Frame
from oricf.imaging import Box, Detection
from tests.support.data import video_frames
from tests.support.fuzzing import examples

EXAMPLES = examples(150)
MAX_CLIENTS = 4
MAX_MESSAGE_BYTES = 4096
SUBPROTOCOL = ["foxglove.sdk.v1"]


class Fed:
    """A live view fed by a thread of its own, as a route would feed it."""

    def __init__(self) -> None:
        self.view = LiveView(LiveViewConfig(listen="127.0.0.1:0", max_fps=30,
                                            max_clients=MAX_CLIENTS,
                                            max_message_bytes=MAX_MESSAGE_BYTES))
        self.shown = 0
        self.slowest_show_s = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._feed, daemon=True)

    def _feed(self) -> None:
        frame = Frame.from_pixels(video_frames([0])[0])
        people = [Detection("person", 0, 0.9, Box(10, 20, 60, 200), track_id=1)]
        while not self._stop.wait(0.02):
            started = time.perf_counter()
            self.view.show("cam", {"route": "cam", "image": frame, "detections": people,
                                   "count": len(people), "answer": "one person"})
            self.slowest_show_s = max(self.slowest_show_s, time.perf_counter() - started)
            self.shown += 1

    def __enter__(self) -> Fed:
        self.view.start()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.view.stop()


@pytest.fixture(scope="module")
def fed() -> Iterator[Fed]:
    with Fed() as running:
        yield running


def wait_for_no_viewers(fed: Fed, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while fed.view.front is not None and fed.view.front.viewers:
        assert time.monotonic() < deadline, f"{fed.view.front.viewers} viewers still held"
        time.sleep(0.01)


def serves_a_viewer(fed: Fed) -> None:
    """Once the viewers before have left, a well-behaved one still gets serverInfo, the
    channels and a frame."""
    wait_for_no_viewers(fed)
    shown = fed.shown
    with connect(fed.view.url, subprotocols=SUBPROTOCOL, open_timeout=10) as viewer:  # type: ignore[arg-type]
        assert json.loads(viewer.recv(timeout=10))["op"] == "serverInfo"
        advertised = json.loads(viewer.recv(timeout=10))
        assert advertised["op"] == "advertise"
        image = next(c["id"] for c in advertised["channels"] if c["topic"] == "/cam/image")
        viewer.send(json.dumps({"op": "subscribe",
                                "subscriptions": [{"id": 1, "channelId": image}]}))
        while not isinstance(frame := viewer.recv(timeout=10), bytes):
            pass
        assert frame[0] == 1
    assert fed.shown > shown  # the feeder went on meanwhile
    assert fed.slowest_show_s < 0.5, fed.slowest_show_s  # a bound on blocking, not a timing


OPS = st.sampled_from(["subscribe", "unsubscribe", "advertise", "unadvertise",
                       "getParameters", "setParameters", "subscribeParameterUpdates",
                       "subscribeConnectionGraph", "fetchAsset", "callService", "nonsense",
                       "", "serverInfo"])
JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(),
              st.text(max_size=40)),
    lambda children: st.one_of(st.lists(children, max_size=4),
                               st.dictionaries(st.text(max_size=12), children, max_size=4)),
    max_leaves=12)


@st.composite
def text_messages(draw: st.DrawFn) -> str:
    kind = draw(st.integers(0, 3))
    if kind == 0:  # a known or unknown op with random fields
        fields = draw(st.dictionaries(st.sampled_from(
            ["subscriptions", "subscriptionIds", "channels", "channelIds", "id", "channelId",
             "parameterNames", "uri", "requestId", "names"]), JSON_VALUES, max_size=3))
        return json.dumps({"op": draw(OPS), **fields})
    if kind == 1:  # subscriptions to channels that do or do not exist
        ids = draw(st.lists(st.integers(-5, 2**40), max_size=5))
        return json.dumps({"op": "subscribe",
                           "subscriptions": [{"id": i, "channelId": c} for i, c in
                                             enumerate(ids)]})
    if kind == 2:
        return draw(st.text(max_size=200))  # not JSON, or JSON of another shape
    return json.dumps(draw(JSON_VALUES))


BINARY = st.one_of(st.binary(max_size=300),
                   st.builds(lambda op, rest: bytes([op]) + rest, st.integers(0, 255),
                             st.binary(max_size=64)),
                   # Client Message Data on a channel the viewer never advertised
                   st.builds(lambda channel, data: b"\x01" + channel.to_bytes(4, "little") + data,
                             st.integers(0, 2**32 - 1), st.binary(max_size=64)))


def test_any_messages_from_a_viewer_leave_the_view_serving(
        fed: Fed, caplog: pytest.LogCaptureFixture) -> None:
    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(st.one_of(text_messages(), BINARY), min_size=1, max_size=6))
    def run(messages: list[str | bytes]) -> None:
        with suppress(ConnectionClosed, TimeoutError), connect(
                fed.view.url, subprotocols=SUBPROTOCOL) as viewer:  # type: ignore[arg-type]
            for message in messages:
                viewer.send(message)
            with suppress(TimeoutError):
                viewer.recv(timeout=0.05)
        wait_for_no_viewers(fed)  # a viewer that left frees its place

    with caplog.at_level(logging.INFO):
        run()
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert not errors, (len(errors), errors[:3])
    serves_a_viewer(fed)


RAW_REQUESTS = st.one_of(
    st.binary(max_size=400),
    st.builds(lambda protocol, key, extra: (
        f"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n{protocol}{extra}\r\n"
        ).encode("utf-8", "replace"),
        st.sampled_from(["", "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n",
                         "Sec-WebSocket-Protocol: nonsense\r\n",
                         "Sec-WebSocket-Protocol: " + "x," * 500 + "\r\n"]),
        st.sampled_from(["dGhlIHNhbXBsZSBub25jZQ==", "", "not base64", "A" * 3000]),
        st.sampled_from(["", "Content-Length: 99999999\r\n", "X: " + "y" * 9000 + "\r\n",
                         "Transfer-Encoding: chunked\r\n"])))


def test_any_bytes_instead_of_a_handshake_are_answered_or_closed(fed: Fed) -> None:
    host, port = "127.0.0.1", int(fed.view.url.rsplit(":", 1)[1])

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(RAW_REQUESTS)
    def run(request: bytes) -> None:
        with socket.create_connection((host, port), timeout=5) as raw, suppress(OSError):
            raw.sendall(request)
            raw.shutdown(socket.SHUT_WR)
            while raw.recv(65536):  # an answer, then the close; never a hang
                pass

    run()
    serves_a_viewer(fed)


def test_a_viewer_without_a_foxglove_subprotocol_is_closed(fed: Fed) -> None:
    for offered in (None, ["nonsense.v9"]):
        with suppress(InvalidStatus), connect(
                fed.view.url, subprotocols=offered) as viewer:  # type: ignore[arg-type]
            with pytest.raises(ConnectionClosed) as closed:
                viewer.recv(timeout=5)
            assert closed.value.rcvd is not None and closed.value.rcvd.code == 1002
    serves_a_viewer(fed)


def test_a_message_over_the_limit_closes_its_viewer(fed: Fed) -> None:
    with connect(fed.view.url, subprotocols=SUBPROTOCOL) as viewer:  # type: ignore[arg-type]
        viewer.send("x" * (MAX_MESSAGE_BYTES + 1))
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                viewer.recv(timeout=5)
        assert closed.value.sent is not None and closed.value.sent.code == 1009
    serves_a_viewer(fed)


def test_one_viewer_too_many_is_refused(fed: Fed) -> None:
    with ExitStack() as viewers:
        for _ in range(MAX_CLIENTS):
            viewers.enter_context(connect(fed.view.url, subprotocols=SUBPROTOCOL))  # type: ignore[arg-type]
        deadline = time.monotonic() + 5
        while fed.view.front is not None and fed.view.front.viewers < MAX_CLIENTS:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        with pytest.raises(InvalidStatus) as refused:
            connect(fed.view.url, subprotocols=SUBPROTOCOL)  # type: ignore[arg-type]
        assert refused.value.response.status_code == 503
    serves_a_viewer(fed)


def test_connections_that_never_finish_their_handshake_are_closed(
        fed: Fed, monkeypatch: pytest.MonkeyPatch) -> None:
    host, port = "127.0.0.1", int(fed.view.url.rsplit(":", 1)[1])
    idle = [socket.create_connection((host, port), timeout=front.HANDSHAKE_TIMEOUT_S + 10)
            for _ in range(20)]
    try:
        serves_a_viewer(fed)  # meanwhile
        for sock in idle:
            assert sock.recv(1) == b""  # closed by the server, not left open
    finally:
        for sock in idle:
            sock.close()


def test_what_a_viewer_sends_cannot_forge_log_lines(fed: Fed,
                                                    caplog: pytest.LogCaptureFixture) -> None:
    """The SDK logs an unparsable message with the viewer's words in it: escaped, clipped,
    and a warning (a viewer's mistake is no error of the gateway)."""
    with caplog.at_level(logging.INFO), suppress(ConnectionClosed), connect(
            fed.view.url, subprotocols=SUBPROTOCOL) as viewer:  # type: ignore[arg-type]
        viewer.send(json.dumps({"op": "evil\n12:00:00 ERROR forged" + "x" * 3000}))
        deadline = time.monotonic() + 10
        while not any("forged" in r.getMessage() for r in caplog.records):
            assert time.monotonic() < deadline, caplog.text
            time.sleep(0.05)
    sdk = [r for r in caplog.records if r.name.startswith("foxglove")]
    assert all("\n" not in r.getMessage() and len(r.getMessage()) < 400 for r in sdk)
    assert all(r.levelno <= logging.WARNING for r in sdk if "forged" in r.getMessage())
    serves_a_viewer(fed)
