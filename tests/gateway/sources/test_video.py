"""The gateway without ROS: a video file in, JSON lines out, rclpy never imported; and the
video source's bad cases (a file that does not exist ends its route with a clear error)."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import pytest
import yaml

from oricf.config import config_dir
from oricf.gateway.config import InputConfig
from oricf.gateway.sources.video_source import VideoSource
from tests.support.data import video_path
from tests.support.services import RunningService

PIPELINE = config_dir() / "pipelines" / "people_video.yaml"


def test_people_video_pipeline_writes_counts_as_json_lines_without_ros(
        tmp_path: Path, detector: RunningService) -> None:
    no_ros = tmp_path / "no_ros" / "rclpy"
    no_ros.mkdir(parents=True)
    (no_ros / "__init__.py").write_text("raise ImportError('rclpy must not be imported')\n")
    overlay = tmp_path / "here.yaml"
    overlay.write_text(yaml.safe_dump({
        "endpoints": {"detector": {"address": detector.address}},
        "routes": {"people": {"input": {"url": str(video_path()), "fps": 100}}}}))
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "gateway", "--config", str(PIPELINE),
         "--overlay", str(overlay)], capture_output=True, text=True, timeout=300,
        env={"PYTHONPATH": str(no_ros.parent), "PATH": "/usr/bin:/bin",
             "HOME": str(Path.home())}, check=False)
    assert result.returncode == 0, result.stderr
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert len(lines) >= 20, result.stderr
    assert all(line["route"] == "people" and 1 <= line["count"] <= 15 for line in lines)
    assert "vtest.avi ended after 795 frames" in result.stderr


def test_a_missing_file_ends_its_route_with_a_clear_error(caplog: object) -> None:
    ended = threading.Event()
    source = VideoSource("cam", InputConfig(url="/nowhere/video.mp4"), lambda load: None,
                         lambda route: ended.set())
    source.start()
    assert ended.wait(10)
    assert source.frames == 0
    assert "cannot open /nowhere/video.mp4; the route ends" in caplog.text  # type: ignore[attr-defined]


def test_annotated_frames_go_to_a_folder_a_video_and_a_latest_image(
        tmp_path: Path, detector: RunningService) -> None:
    """--set replaces the route's post-processing and outputs (YAML values, validated)."""
    folder, video, latest = tmp_path / "frames", tmp_path / "out.avi", tmp_path / "latest.jpg"
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "gateway", "--config", str(PIPELINE),
         "--set", f"endpoints.detector.address={detector.address}",
         "--set", f"routes.people.input.url={video_path()}",
         "--set", "routes.people.input.fps=100",
         "--set", "routes.people.post=[{count: {label: person}}, {annotate: {}}]",
         "--set", f"routes.people.outputs=[{{jsonl: '-', from: count}}, "
                  f"{{frames: '{folder}', from: annotated}}, "
                  f"{{frames: '{video}', from: annotated}}, "
                  f"{{frames: '{latest}', from: annotated}}]"],
        capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    counted = len(result.stdout.splitlines())
    images = sorted(folder.glob("people-*.jpg"))
    assert counted >= 20 and len(images) == counted, (counted, len(images))
    first = cv2.imread(str(images[0]))
    assert first is not None and first.shape == (576, 768, 3)
    capture = cv2.VideoCapture(str(video))
    assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == counted
    assert cv2.imread(str(latest)).shape == (576, 768, 3)
    assert not list(tmp_path.glob(".*partial*"))


def test_a_set_with_a_bad_value_is_refused_naming_the_key() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "oricf", "gateway", "--config", str(PIPELINE), "--check",
         "--set", "routes.people.input.fps=fast"], capture_output=True, text=True,
        timeout=60, check=False)
    assert result.returncode == 2
    assert "people_video.yaml + --set: routes.people.input.fps" in result.stderr


def test_a_camera_device_that_does_not_exist_is_retried_with_a_logged_error(
        caplog: pytest.LogCaptureFixture) -> None:
    """A USB camera may be plugged in later: the route waits for it, saying so."""
    ended = threading.Event()
    source = VideoSource("cam", InputConfig(url="/dev/video63"), lambda load: None,
                         lambda route: ended.set())
    source.start()
    try:
        deadline = time.monotonic() + 20
        while source.reconnects < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        source.stop()
    assert source.reconnects >= 2 and source.frames == 0
    assert "cannot open /dev/video63; trying again in 0.5 s" in caplog.text
