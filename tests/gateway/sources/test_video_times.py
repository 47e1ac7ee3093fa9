"""A video file's frames carry their position in the file as the time they were taken
(FRAME_TIME), however fast the file is read, and each pass of a looping file follows the
last in time."""

from __future__ import annotations

import threading
from pathlib import Path

import cv2
import pytest

from oricf.gateway.config import InputConfig
from oricf.gateway.route import Loader
from oricf.gateway.sources.video_source import VideoSource
from oricf.gateway.values import FRAME_TIME
from tests.support.data import video_frames

FPS = 8.0
LENGTH = 12


def short_video(path: Path) -> Path:
    """LENGTH frames of vtest.avi, small, at FPS."""
    frames = video_frames(list(range(LENGTH)), (160, 120))
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), FPS, (160, 120))
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def test_a_looping_file_read_as_fast_as_it_decodes_is_timed_by_its_position(
        tmp_path: Path) -> None:
    loads: list[Loader] = []
    enough = threading.Event()

    def submit(load: Loader) -> None:
        loads.append(load)
        if len(loads) >= 3 * LENGTH:
            enough.set()

    source = VideoSource("cam", InputConfig(url=str(short_video(tmp_path / "v.avi")),
                                            loop=True), submit, lambda route: None)
    source.start()
    try:
        assert enough.wait(30)
    finally:
        source.stop()
    times = [load()[FRAME_TIME] for load in loads[:3 * LENGTH]]
    assert times == pytest.approx([i / FPS for i in range(3 * LENGTH)], abs=1e-3)
