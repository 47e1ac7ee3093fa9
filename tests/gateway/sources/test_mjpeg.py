"""Motion JPEG over HTTP: the camera's JPEG bytes reach the route as they came (no decoding on
the robot), people are counted from a real MJPEG camera through the gateway, and streams that
lie or break are survived: skipped parts, refused sizes, reconnection, credentials never
logged."""

from __future__ import annotations

import base64
import http.server
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress

import cv2
import numpy as np
import pytest

from oricf.bench.mjpeg_camera import encode_frames
from oricf.gateway.config import InputConfig
from oricf.gateway.sources.mjpeg import MAX_PART_BYTES, BadStream, MjpegStream, NotMjpeg
from oricf.gateway.sources.video_source import VideoSource
from oricf.gateway.values import Frame
from oricf.launch.health import free_port
from tests.gateway.sources.test_rtsp import counts, gateway
from tests.support.services import RunningService
from tests.support.waiting import wait_for

JPEGS = encode_frames(3)
PNG = cv2.imencode(".png", np.zeros((8, 8, 3), np.uint8))[1].tobytes()


def part(body: bytes, length: int | None = None) -> bytes:
    """One multipart part with its Content-Length (the body's own unless one is given)."""
    size = len(body) if length is None else length
    return b"--cam\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n%s\r\n" % (size, body)


@contextmanager
def http_camera(body: Callable[[], bytes], content_type: str = "multipart/x-mixed-replace;"
                " boundary=cam", user: str | None = None) -> Iterator[str]:
    """An HTTP server on localhost answering every GET with `body()` (then closing)."""
    class Camera(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            expected = "Basic " + base64.b64encode(user.encode()).decode() if user else None
            if expected and self.headers.get("Authorization") != expected:
                self.send_response(401)
                self.end_headers()
                return
            self.send_response(200)
            self.send_header("Content-Type", content_type)
            self.end_headers()
            with suppress(BrokenPipeError, ConnectionResetError):
                self.wfile.write(body())

        def log_message(self, format: str, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Camera)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/video"
    finally:
        server.shutdown()
        server.server_close()


def frames_of(url: str) -> list[Frame]:
    stream = MjpegStream(url, timeout_s=5)
    try:
        return list(iter(stream.read, None))
    finally:
        stream.release()


def test_the_cameras_jpeg_bytes_reach_the_route_as_they_came() -> None:
    body = b"".join(part(jpeg) for jpeg in JPEGS) + b"--cam--\r\n"
    with http_camera(lambda: body) as url:
        frames = frames_of(url)
    assert [f.data for f in frames] == JPEGS
    assert all((f.encoding, f.width, f.height) == ("jpeg", 640, 480) for f in frames)


def test_parts_without_a_length_and_a_boundary_declared_with_dashes() -> None:
    body = b"".join(b"--cam\r\nContent-Type: image/jpeg\r\n\r\n%s\r\n" % j for j in JPEGS)
    with http_camera(lambda: body + b"--cam--\r\n",
                     "multipart/x-mixed-replace;boundary=--cam") as url:
        frames = frames_of(url)
    assert [f.data for f in frames] == JPEGS


def test_a_part_that_is_not_a_jpeg_is_skipped_and_counted() -> None:
    body = part(JPEGS[0]) + part(PNG) + part(b"not an image") + part(JPEGS[1])
    with http_camera(lambda: body) as url:
        stream = MjpegStream(url, timeout_s=5)
        frames = list(iter(stream.read, None))
        stream.release()
    assert [f.data for f in frames] == JPEGS[:2] and stream.skipped == 2


@pytest.mark.parametrize(("body", "message"), [
    (part(JPEGS[0], length=10**12), "Content-Length b'1000000000000' refused"),
    (part(JPEGS[0], length=-5), "Content-Length b'-5' refused"),
    (b"--cam\r\n" + b"X-Header-Without-Colon\r\n\r\n", "malformed part header"),
    (b"--cam\r\n" + b"".join(b"X-%d: 1\r\n" % i for i in range(40)) + b"\r\n",
     "malformed part header"),
])
def test_a_lying_part_header_drops_the_connection(body: bytes, message: str) -> None:
    with http_camera(lambda: body) as url, pytest.raises(BadStream, match=message):
        frames_of(url)


def test_a_stream_without_boundaries_is_refused_without_growing() -> None:
    chunk = b"x" * 1000 + b"\n"
    with http_camera(lambda: chunk * (MAX_PART_BYTES // len(chunk) + 10)) as url, \
            pytest.raises(BadStream, match="no boundary"):
        frames_of(url)


def test_a_stream_cut_in_the_middle_of_a_part_ends_without_a_frame() -> None:
    body = part(JPEGS[0]) + part(JPEGS[1])[:-1000]
    with http_camera(lambda: body) as url:
        assert [f.data for f in frames_of(url)] == JPEGS[:1]


def test_another_kind_of_stream_is_left_to_ffmpeg() -> None:
    with http_camera(lambda: b"#EXTM3U\n", "application/vnd.apple.mpegurl") as url, \
            pytest.raises(NotMjpeg):
        MjpegStream(url, timeout_s=5)


def test_credentials_open_the_camera_and_never_reach_the_log(
        caplog: pytest.LogCaptureFixture) -> None:
    body = b"".join(part(jpeg) for jpeg in JPEGS) + b"--cam--\r\n"
    with http_camera(lambda: body, user="robot:s3cret") as url:
        host = url.removeprefix("http://")
        assert [f.data for f in frames_of(f"http://robot:s3cret@{host}")] == JPEGS
        ended = threading.Event()
        source = VideoSource("cam", InputConfig(url=f"http://robot:wrong@{host}"),
                             lambda load: None, lambda route: ended.set())
        source.start()
        deadline = time.monotonic() + 20
        while source.reconnects < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        source.stop()
    assert source.reconnects >= 2 and source.frames == 0
    assert f"cannot open {url} (" in caplog.text  # the server's words, quoted or not
    assert "HTTP Error 401: Unauthorized" in caplog.text
    assert "wrong" not in caplog.text and "s3cret" not in caplog.text


def test_people_are_counted_from_an_mjpeg_camera_that_restarts(detector: RunningService) -> None:
    """bench/mjpeg_camera.py (vtest.avi as MJPEG at 10 fps) through the gateway; the camera
    is killed and started again on the same port."""
    port = free_port()

    def camera() -> subprocess.Popen[str]:
        process = subprocess.Popen([sys.executable, "-m", "oricf.bench.mjpeg_camera", str(port),
                                    "--frames", "30"], stdout=subprocess.PIPE, text=True)
        assert process.stdout is not None and process.stdout.readline().strip() == "ready"
        return process

    url = f"http://127.0.0.1:{port}/"
    first = camera()
    with gateway(detector.address, url) as (lines, log):
        before = counts(lines, 10, timeout=60)
        first.kill()
        first.wait()
        wait_for(lambda: f"{url} stopped sending; reconnecting" in "".join(log), timeout=60,
                 what="the gateway noticing the camera gone")
        second = camera()
        try:
            while not lines.empty():
                lines.get_nowait()
            after = counts(lines, 10, timeout=60)
        finally:
            second.kill()
            second.wait()
        text = "".join(log)
    assert len(before) == 10 and all(1 <= c <= 15 for c in before), text
    assert len(after) == 10 and all(1 <= c <= 15 for c in after), text
    assert text.count(f"{url} opened") >= 2 and "Traceback" not in text
