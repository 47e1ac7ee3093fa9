"""Motion JPEG cameras that act against the gateway, on real servers on localhost: a redirect
to another host (the password stays behind), cameras that accept and drop every connection
(reconnects back off, warnings are throttled), and cameras that drip bytes or send header
lines without end (a deadline per step, a logged reconnect, and stop() at once)."""

from __future__ import annotations

import base64
import http.server
import logging
import socket
import socketserver
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress

import pytest

from oricf.gateway.config import InputConfig
from oricf.gateway.sources import video_source
from oricf.gateway.sources.mjpeg import BadStream, MjpegStream
from oricf.gateway.sources.video_source import VideoSource
from tests.gateway.sources.test_mjpeg import JPEGS, part

MJPEG_HEADERS = (b"HTTP/1.0 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary=cam"
                 b"\r\n\r\n")
SECRET = "Basic " + base64.b64encode(b"robot:s3cret").decode()


@contextmanager
def serving(handler: type[socketserver.BaseRequestHandler]) -> Iterator[int]:
    """A threading TCP server on a free localhost port; yields the port."""
    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


@contextmanager
def http_server(answer: Callable[[http.server.BaseHTTPRequestHandler], None]) -> Iterator[int]:
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            with suppress(BrokenPipeError, ConnectionResetError):
                answer(self)

        def log_message(self, format: str, *args: object) -> None:
            pass

    with serving(Handler) as port:
        yield port


def serve_mjpeg(request: http.server.BaseHTTPRequestHandler) -> None:
    request.send_response(200)
    request.send_header("Content-Type", "multipart/x-mixed-replace; boundary=cam")
    request.end_headers()
    request.wfile.write(b"".join(part(j) for j in JPEGS) + b"--cam--\r\n")


def test_a_redirect_to_another_origin_leaves_the_password_behind() -> None:
    seen: list[str | None] = []

    def elsewhere(request: http.server.BaseHTTPRequestHandler) -> None:
        seen.append(request.headers.get("Authorization"))
        serve_mjpeg(request)

    with http_server(elsewhere) as other:
        def camera(request: http.server.BaseHTTPRequestHandler) -> None:
            if request.path == "/here":  # a redirect within the camera's own origin
                assert request.headers.get("Authorization") == SECRET
                serve_mjpeg(request)
                return
            target = "/here" if request.path == "/same" else f"http://127.0.0.1:{other}/v"
            request.send_response(302)
            request.send_header("Location", target)
            request.end_headers()

        with http_server(camera) as port:
            for path in ("/same", "/away"):
                stream = MjpegStream(f"http://robot:s3cret@127.0.0.1:{port}{path}", 5)
                assert [f.data for f in iter(stream.read, None)] == JPEGS
                stream.release()
    assert seen == [None]  # the other server was asked once, without the credentials


@pytest.mark.parametrize("body", [b"", part(JPEGS[0]) + b"--cam\r\nno colon here\r\n\r\n"],
                         ids=["closed-at-once", "one-frame-then-a-bad-part"])
def test_a_camera_that_drops_every_connection_is_not_hammered(
        body: bytes, caplog: pytest.LogCaptureFixture) -> None:
    connections = []

    class Dropping(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            connections.append(time.monotonic())
            self.request.recv(4096)
            self.request.sendall(MJPEG_HEADERS + body)

    with serving(Dropping) as port:
        source = VideoSource("cam", InputConfig(url=f"http://127.0.0.1:{port}/"),
                             lambda load: None, lambda route: None)
        source.start()
        time.sleep(4)
        source.stop()
    # Waits of 0.5, 1 and 2 s: four connections in 4 s, where none gave thousands.
    assert 2 <= len(connections) <= 5, len(connections)
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) <= 4, [r.getMessage() for r in warnings]


def drip(sock: socket.socket, data: bytes, every_s: float = 0.2) -> None:
    """A byte every 0.2 s: a socket timeout never trips. After 5 s the camera gives up."""
    for byte in data[:25]:
        sock.sendall(bytes([byte]))
        time.sleep(every_s)


HEADER = b"--cam\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % len(JPEGS[0])
STALLS: dict[str, Callable[[socket.socket], None]] = {
    "answer": lambda sock: drip(sock, MJPEG_HEADERS),
    "part header": lambda sock: (sock.sendall(MJPEG_HEADERS), drip(sock, HEADER)),
    "part": lambda sock: (sock.sendall(MJPEG_HEADERS + HEADER), drip(sock, JPEGS[0])),
    "endless headers": lambda sock: sock.sendall(MJPEG_HEADERS + b"--cam\r\n"
                                                 + b"X-Again: 1\r\n" * 5000),
}
CUT_OFF = {"answer": "no answer in 1 s", "part header": "took over 1 s", "part": "took over 1 s",
           "endless headers": "over 32 lines"}


def stalling(script: Callable[[socket.socket], None],
             connections: list[float] | None = None) -> type[socketserver.BaseRequestHandler]:
    class Stalling(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            if connections is not None:
                connections.append(time.monotonic())
            self.request.recv(4096)
            with suppress(OSError):
                script(self.request)

    return Stalling


@pytest.mark.parametrize("stall", list(STALLS))
def test_a_camera_that_drips_or_never_ends_a_header_block_is_cut_off(stall: str) -> None:
    started = time.monotonic()
    with serving(stalling(STALLS[stall])) as port, \
            pytest.raises(BadStream, match=CUT_OFF[stall]):
        stream = MjpegStream(f"http://127.0.0.1:{port}/", timeout_s=1)
        try:
            list(iter(stream.read, None))
        finally:
            stream.release()
    assert time.monotonic() - started < 4


def test_a_dripping_camera_is_reconnected_with_a_log_line_and_stop_is_prompt(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    monkeypatch.setattr(video_source, "STREAM_TIMEOUT_MS", 1000)
    connections: list[float] = []
    with serving(stalling(STALLS["part"], connections)) as port:
        source = VideoSource("cam", InputConfig(url=f"http://127.0.0.1:{port}/"),
                             lambda load: None, lambda route: None)
        source.start()
        deadline = time.monotonic() + 10
        while len(connections) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)  # the second connection is dripping a part
        stopping = time.monotonic()
        source.stop()
        stopped_in = time.monotonic() - stopping
    assert source.reconnects >= 1
    assert "a part took over 1 s" in caplog.text
    assert stopped_in < 1, stopped_in
