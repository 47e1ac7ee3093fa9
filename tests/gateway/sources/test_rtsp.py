"""Streams into the gateway without ROS: a real RTSP camera (GStreamer's RTSP server, fed
vtest.avi as H.264 by FFmpeg) and an HLS stream from a real HTTP server. People are counted
from them; the gateway survives the RTSP server being killed and started again (a logged
reconnect, counts resume); an address where no server answers is retried, logged, and
never ends the gateway."""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

import pytest

from oricf.bench.rtsp_camera import RtspCamera
from oricf.config import config_dir
from oricf.launch.health import free_port
from tests.support.data import video_path
from tests.support.services import RunningService
from tests.support.waiting import wait_for

PIPELINE = config_dir() / "pipelines" / "people_video.yaml"


def pump(stream: IO[str], lines: queue.Queue[str], log: list[str] | None = None) -> None:
    for line in stream:
        lines.put(line)
        if log is not None:
            log.append(line)


@contextmanager
def gateway(detector: str, url: str) -> Iterator[tuple[queue.Queue[str], list[str]]]:
    """`oricf gateway` on people_video.yaml reading `url`: (JSON lines, its log so far)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "oricf", "gateway", "--config", str(PIPELINE),
         "--set", f"endpoints.detector.address={detector}",
         "--set", f"routes.people.input.url={url}", "--set", "routes.people.input.fps=5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout is not None and process.stderr is not None
    lines: queue.Queue[str] = queue.Queue()
    log: list[str] = []
    threading.Thread(target=pump, args=(process.stdout, lines), daemon=True).start()
    threading.Thread(target=pump, args=(process.stderr, queue.Queue(), log), daemon=True).start()
    try:
        yield lines, log
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(30) == 0, "".join(log)[-3000:]


def counts(lines: queue.Queue[str], wanted: int, timeout: float) -> list[int]:
    found: list[int] = []
    deadline = time.monotonic() + timeout
    while len(found) < wanted and time.monotonic() < deadline:
        try:
            record = json.loads(lines.get(timeout=max(0.1, deadline - time.monotonic())))
        except queue.Empty:
            break
        found.append(record["count"])
    return found


def drain(lines: queue.Queue[str]) -> None:
    while not lines.empty():
        lines.get_nowait()


def test_people_are_counted_from_an_rtsp_camera_that_restarts(detector: RunningService) -> None:
    with RtspCamera() as camera:
        camera.play_file(video_path())
        with gateway(detector.address, camera.url) as (lines, log):
            before = counts(lines, 10, timeout=60)
            assert len(before) == 10 and all(1 <= c <= 15 for c in before), "".join(log)
            camera.stop_server()
            # the gateway notices, and retries while the server is away
            wait_for(lambda: f"cannot open {camera.url}; trying again in" in "".join(log),
                     timeout=60, what="a retry while the server is away")
            drain(lines)
            camera.start_server()
            after = counts(lines, 10, timeout=60)
            assert len(after) == 10 and all(1 <= c <= 15 for c in after), "".join(log)
        text = "".join(log)
    assert f"{camera.url} stopped sending; reconnecting" in text
    assert f"cannot open {camera.url}; trying again in" in text
    assert text.count(f"{camera.url} opened") >= 2


def test_an_address_where_no_camera_answers_is_retried_and_the_gateway_stays(
        detector: RunningService) -> None:
    url = f"rtsp://127.0.0.1:{free_port()}/cam"
    with gateway(detector.address, url) as (_, log):
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and "".join(log).count("cannot open") < 3:
            time.sleep(0.5)
        text = "".join(log)
    assert text.count(f"cannot open {url}; trying again in") >= 3, text
    assert "Traceback" not in text


@pytest.mark.long
def test_people_are_counted_from_an_hls_stream_over_http(tmp_path: Path,
                                                         detector: RunningService) -> None:
    """FFmpeg cuts vtest.avi into HLS segments; a real HTTP server serves them."""
    subprocess.run(["ffmpeg", "-hide_banner", "-loglevel", "error", "-t", "10", "-i",
                    str(video_path()), "-an", "-c:v", "libx264", "-preset", "ultrafast",
                    "-g", "10", "-hls_time", "2", "-hls_playlist_type", "vod",
                    str(tmp_path / "cam.m3u8")], check=True, timeout=120)
    port = free_port()
    server = subprocess.Popen([sys.executable, "-m", "http.server", str(port), "--bind",
                               "127.0.0.1", "--directory", str(tmp_path)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with gateway(detector.address, f"http://127.0.0.1:{port}/cam.m3u8") as (lines, log):
            found = counts(lines, 10, timeout=60)
    finally:
        server.kill()
        server.wait()
    assert len(found) == 10 and all(1 <= c <= 15 for c in found), "".join(log)
