"""People tracked in a video answer "how many people have you seen in the last minute?":
the shipped people_tracked pipeline with the real detector and the real language model
(with the tracking prompt), over its text channel. The answer states the number of
different people the `seen_tracks` step counted."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import pytest

from oricf.config import config_dir
from oricf.launch.health import free_port
from tests.support.data import video_frames
from tests.support.services import RunningService, running_service

PIPELINE = config_dir() / "pipelines" / "people_tracked.yaml"
PROMPT = config_dir() / "prompts" / "gemma3-270m-tracks.yaml"
FRAMES = 60


@pytest.fixture(scope="module")
def services(detector: RunningService) -> Iterator[dict[str, str]]:
    with running_service("llm", {"prompts": {"gemma3-270m": str(PROMPT)}}) as llm:
        yield {"detector": detector.address, "llm": llm.address}


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """vtest.avi's first 6 s, in which people come and go."""
    path = tmp_path_factory.mktemp("video") / "clip.avi"
    frames = video_frames(list(range(FRAMES)))
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10,
                             (frames[0].shape[1], frames[0].shape[0]))
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


class Lines:
    """A stream's lines, read by a thread as they come."""

    def __init__(self, stream: object) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream: object) -> None:
        for line in stream:  # type: ignore[attr-defined]
            self.lines.append(line)

    def wait_for(self, text: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not any(text in line for line in self.lines):
            assert time.monotonic() < deadline, f"no {text!r} in:\n{''.join(self.lines)[-3000:]}"
            time.sleep(0.2)


def ask(port: int, question: str) -> str:
    with socket.create_connection(("127.0.0.1", port), timeout=120) as sock:
        sock.sendall(f"{question}\n".encode())
        return sock.makefile("r", encoding="utf-8").readline().strip()


def test_how_many_people_were_seen_in_the_last_minute(services: dict[str, str],
                                                      clip: Path) -> None:
    port = free_port()
    sets = {"endpoints.detector.address": services["detector"],
            "endpoints.llm.address": services["llm"],
            "channels.questions.listen": f"127.0.0.1:{port}",
            "routes.people.input.url": str(clip),
            # the values must stay fresh after the clip ends, while the question is asked
            **{f"routes.people.outputs.{i}.max_age_s": "600" for i in range(3)}}
    command = [sys.executable, "-m", "oricf", "gateway", "--config", str(PIPELINE)]
    for key, value in sets.items():
        command += ["--set", f"{key}={value}"]
    gateway = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        stdout, stderr = Lines(gateway.stdout), Lines(gateway.stderr)
        stderr.wait_for(f"ended after {FRAMES} frames", timeout=120)
        time.sleep(2)  # the last frames through the detector
        seen = [json.loads(line)["people_last_minute"] for line in stdout.lines]
        assert seen and seen == sorted(seen), seen  # nobody falls out of a minute in 6 s
        answer = ask(port, "How many people have you seen in the last minute?")
    finally:
        gateway.send_signal(signal.SIGTERM)
        gateway.wait(timeout=30)
    assert 5 <= seen[-1] <= 12, seen  # vtest.avi's first 6 s: people come and go
    assert re.findall(r"\d+", answer) == [str(seen[-1])], (answer, seen[-1])
    assert gateway.returncode == 0, "".join(stderr.lines)[-2000:]
