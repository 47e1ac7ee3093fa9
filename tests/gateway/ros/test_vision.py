"""Detections as vision_msgs/Detection2DArray: the gateway tracks people in a video and
publishes each frame's detections with their track ids; a plain rclpy subscriber receives
the same detections the JSON lines output writes, and so does a recording's reader.
vision_msgs is built from its definitions (tests/support/vision_msgs.py); without it, a
pipeline asking for it is refused at start."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import cv2
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from tests.support.data import video_frames
from tests.support.services import RunningService
from tests.support.vision_msgs import build, environment

TOPIC = "/people/detections"
MESSAGES = 8
SUBSCRIBER = textwrap.dedent(f"""
    import json, rclpy
    from rclpy.node import Node
    from vision_msgs.msg import Detection2DArray
    rclpy.init()
    node = Node("vision_probe")
    got = []
    def on_message(msg):
        got.append([[d.id, d.results[0].hypothesis.class_id, d.results[0].hypothesis.score,
                     d.bbox.center.position.x, d.bbox.center.position.y, d.bbox.size_x,
                     d.bbox.size_y] for d in msg.detections])
    node.create_subscription(Detection2DArray, "{TOPIC}", on_message, 10)
    print("ready", flush=True)
    while len(got) < {MESSAGES}:
        rclpy.spin_once(node, timeout_sec=1)
    print(json.dumps(got), flush=True)
""")


@pytest.fixture(scope="module")
def vision_env() -> dict[str, str]:
    return environment(build())


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("video") / "clip.avi"
    frames = video_frames(list(range(30)))
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10,
                             (frames[0].shape[1], frames[0].shape[0]))
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def pipeline(folder: Path, detector: str, clip: Path) -> Path:
    path = folder / "tracked_detections.yaml"
    path.write_text(yaml.safe_dump({
        "node_name": "oricf_vision_test",
        "endpoints": {"detector": {"address": detector, "deadline_ms": 5000}},
        "routes": {"people": {
            "input": {"url": str(clip), "fps": 10, "loop": True},
            "call": {"service": "detector", "method": "Detect", "labels": ["person"],
                     "min_score": 0.1},
            "post": [{"track": {"labels": ["person"]}}],
            "outputs": [{"topic": TOPIC, "type": "vision_msgs/Detection2DArray",
                         "from": "detections"},
                        {"jsonl": "-", "from": "detections"}]}}}))
    return path


def recorded_messages(path: Path) -> list[Any]:
    with path.open("rb") as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        return list(reader.iter_decoded_messages())


def as_rows(detections: list[dict[str, Any]]) -> list[list[Any]]:
    """JSON lines detections in the subscriber's form."""
    rows = []
    for d in detections:
        b = d["box"]
        rows.append([str(d["track_id"]), d["label"], d["score"],
                     (b["x_min"] + b["x_max"]) / 2, (b["y_min"] + b["y_max"]) / 2,
                     b["x_max"] - b["x_min"], b["y_max"] - b["y_min"]])
    return rows


def test_tracked_detections_reach_a_subscriber_as_the_json_lines_carry_them(
        vision_env: dict[str, str], ros_env: dict[str, str], detector: RunningService,
        clip: Path, tmp_path: Path) -> None:
    env = {**vision_env, **ros_env}
    probe = subprocess.Popen([sys.executable, "-c", SUBSCRIBER], env=env, text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    gateway = None
    try:
        assert probe.stdout is not None and probe.stdout.readline().strip() == "ready"
        gateway = subprocess.Popen(
            [sys.executable, "-m", "oricf", "gateway", "--config",
             str(pipeline(tmp_path, detector.address, clip)), "--record",
             str(tmp_path / "run.mcap")],
            env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        received = json.loads(probe.communicate(timeout=180)[0].splitlines()[-1])
    finally:
        probe.kill()
        if gateway is not None:
            gateway.send_signal(signal.SIGTERM)
            stdout, stderr = gateway.communicate(timeout=30)
    lines = [json.loads(line)["detections"] for line in stdout.splitlines()]
    written = [as_rows(d) for d in lines]
    assert len(received) == MESSAGES
    for message in received:
        assert message in written, (message, written[:3])
    ids = {row[0] for message in received for row in message}
    assert ids and all(i.isdigit() for i in ids), ids
    assert {row[1] for message in received for row in message} == {"person"}
    assert all(d["velocity"] is not None for frame in lines for d in frame)
    assert gateway.returncode == 0, stderr[-2000:]
    # --record wrote them without vision_msgs (oricf.gateway.topics.cdr), and a decoder
    # that reads the recording's own definitions finds the same detections
    recorded = [[[d.id, d.results[0].hypothesis.class_id, d.results[0].hypothesis.score,
                  d.bbox.center.position.x, d.bbox.center.position.y, d.bbox.size_x,
                  d.bbox.size_y] for d in msg.detections]
                for _, channel, _, msg in recorded_messages(tmp_path / "run.mcap")
                if channel.topic == TOPIC]
    assert len(recorded) >= MESSAGES and all(m in written for m in recorded)


def test_without_vision_msgs_the_pipeline_is_refused_saying_what_to_install(
        ros_env: dict[str, str], detector: RunningService, clip: Path, tmp_path: Path) -> None:
    gateway = subprocess.run(
        [sys.executable, "-m", "oricf", "gateway", "--config",
         str(pipeline(tmp_path, detector.address, clip))],
        env={**os.environ, **ros_env}, text=True, capture_output=True,
        timeout=120)
    assert gateway.returncode == 2, gateway.stderr[-2000:]
    assert "vision_msgs/Detection2DArray needs the ROS package vision_msgs" in gateway.stderr
    assert "apt install ros-jazzy-vision-msgs" in gateway.stderr
