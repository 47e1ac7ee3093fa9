"""Property-based fuzzing of the gateway's own listeners and readers over real sockets:
Motion JPEG streams from a local HTTP camera (parts with lying lengths, stray boundaries,
header lines with and without colons, bodies that are JPEG, PNG, cut or random) and lines
sent to a text channel (any bytes, invalid UTF-8, over-long lines, wrong tokens, a client
that half-closes after its last line). Whatever comes, the reader hands on only JPEG frames
or stops with an error the video source reconnects on, within its deadline; the channel
answers each line once (an answer or an `error:` line), closes, and serves the next client."""

from __future__ import annotations

import http.server
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import suppress
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from oricf.gateway.channels.server import ChannelConfig, Client, TextChannel
from oricf.gateway.sources.mjpeg import MjpegStream, NotMjpeg
from oricf.gateway.sources.video_source import STREAM_ERRORS
from oricf.launch.health import free_port
from tests.gateway.sources.test_mjpeg import JPEGS, PNG

EXAMPLES = 300
TIMEOUT_S = 2.0

BODIES = st.one_of(st.sampled_from([JPEGS[0], JPEGS[0][:500], PNG, b""]),
                   st.binary(max_size=300),
                   st.builds(lambda j, cut: j[:cut], st.just(JPEGS[1]), st.integers(0, 4000)))
HEADER_LINES = st.one_of(
    st.sampled_from([b"Content-Type: image/jpeg", b"Content-Length: 10", b"X-Timestamp: 1",
                     b"Content-Length: -1", b"Content-Length: 99999999999", b"no colon",
                     b"Content-Length: 1e3", b":"]),
    st.binary(max_size=60).map(lambda b: b.replace(b"\n", b"")))
DELIMITERS = st.sampled_from([b"--cam", b"cam", b"--cam--", b"--other", b"", b"--cam  "])


@st.composite
def parts(draw: st.DrawFn) -> bytes:
    body = draw(BODIES)
    lines = draw(st.lists(HEADER_LINES, max_size=4))
    if draw(st.booleans()):  # most cameras send the true length
        lines.append(b"Content-Length: %d" % len(body))
    return b"\r\n".join([draw(DELIMITERS), *lines, b"", body, b""])


STREAMS = st.tuples(
    st.sampled_from(["multipart/x-mixed-replace; boundary=cam",
                     'multipart/x-mixed-replace; boundary="--cam"',
                     "multipart/x-mixed-replace", "multipart/x-mixed-replace; boundary=",
                     "image/jpeg"]),
    st.lists(parts(), max_size=6).map(b"".join))


@pytest.fixture(scope="module")
def camera() -> Iterator[tuple[list[tuple[str, bytes]], str]]:
    """A local HTTP camera answering with the stream the example put in `current[0]`."""
    current: list[tuple[str, bytes]] = [("text/plain", b"")]

    class Camera(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            content_type, body = current[0]
            self.send_response(200)
            self.send_header("Content-Type", content_type)
            self.end_headers()
            with suppress(BrokenPipeError, ConnectionResetError):
                self.wfile.write(body)

        def log_message(self, format: str, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Camera)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield current, f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()
    server.server_close()


def test_any_multipart_stream_gives_jpeg_frames_or_an_error_in_time(
        camera: tuple[list[tuple[str, bytes]], str]) -> None:
    current, url = camera
    tried: list[int] = []

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(STREAMS)
    def fuzz(stream: tuple[str, bytes]) -> None:
        tried.append(1)
        current[0] = stream
        started = time.monotonic()
        try:
            reader = MjpegStream(url, TIMEOUT_S)
        except NotMjpeg:
            return
        try:
            for frame in iter(reader.read, None):
                assert frame.encoding == "jpeg" and frame.width > 0 and frame.height > 0
        except STREAM_ERRORS:
            pass  # the video source logs it and reconnects
        finally:
            reader.release()
        assert time.monotonic() - started < 3 * TIMEOUT_S

    fuzz()
    assert len(tried) >= EXAMPLES


MAX_LINE = 64
TOKEN = "s3cret-token"
LINES = st.one_of(
    st.binary(max_size=32),
    st.text(max_size=32).map(str.encode),
    st.binary(min_size=128, max_size=400),
    st.sampled_from([b"authorization: Bearer wrong", b"\xff\xfe", b"\x00", b"\r", b"   "]),
).map(lambda b: b.replace(b"\n", b""))


@pytest.fixture(scope="module")
def channel(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TextChannel]:
    tokens = Path(tmp_path_factory.mktemp("channel")) / "tokens"
    tokens.write_text(TOKEN + "\n")
    opened = TextChannel("fuzz", ChannelConfig.model_validate({
        "listen": f"127.0.0.1:{free_port()}", "max_line_bytes": MAX_LINE,
        "auth": {"file": tokens}, "auth_timeout_s": 5, "idle_timeout_s": 5}))
    opened.start()

    def echo(line: str, client: Client) -> None:
        opened.send(f"got {line}", client)

    opened.read_by(echo)
    yield opened
    opened.close()


def exchange(channel: TextChannel, data: bytes) -> list[str]:
    """Sends data, half-closes, and returns every line until the channel closes."""
    host, port = channel.address.rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(data)
        sock.shutdown(socket.SHUT_WR)
        return sock.makefile("r", encoding="utf-8", errors="replace").read().splitlines()


def answered(line: bytes) -> bool:
    """Whether a line gets a reply: a long one always (an error), else if not blank."""
    return len(line) > MAX_LINE or bool(line.decode("utf-8", "replace").strip())


def test_any_lines_get_one_reply_each_and_the_channel_serves_on(channel: TextChannel) -> None:
    tried: list[int] = []

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(st.booleans(), st.lists(LINES, max_size=8))
    def fuzz(with_token: bool, lines: list[bytes]) -> None:
        tried.append(1)
        first = f"authorization: Bearer {TOKEN}".encode() if with_token else b"hello"
        replies = exchange(channel, b"".join(line + b"\n" for line in [first, *lines]))
        if not with_token:
            assert len(replies) == 1 and replies[0].startswith("error: the first line")
            return
        assert len(replies) == sum(map(answered, lines)), (lines, replies)
        assert all(r.startswith(("got ", f"error: a line is at most {MAX_LINE}"))
                   for r in replies), replies

    fuzz()
    assert len(tried) >= EXAMPLES
    assert exchange(channel, f"authorization: Bearer {TOKEN}\nping\n".encode()) == ["got ping"]
