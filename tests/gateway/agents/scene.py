"""What the agent tests run against: real model services in this process, a one-frame
video of the pedestrians (frame 300 of vtest.avi: six people, counted by eye), a pipeline
YAML with an agent policy, and a ROS subscriber on the policy's topics."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from oricf.audio.wav import encode_wav
from tests.support.data import video_frames

FRAME = 300
PEOPLE = 6  # counted by eye; the detector agrees at min_score 0.6
TWIST_TOPIC = "/agent_test/cmd_vel"
ARM_TOPIC = "/agent_test/arm"


def one_frame_video(folder: Path) -> Path:
    """Frame 300 for two seconds, as a Motion JPEG AVI (the pipeline loops it)."""
    frame = video_frames([FRAME])[0]
    path = folder / "people.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 5,
                             (frame.shape[1], frame.shape[0]))
    for _ in range(10):
        writer.write(frame)
    writer.release()
    return path


def silent_wav(folder: Path) -> Path:
    """Half a second of silence: the speech route has a source, and hears nothing in it."""
    path = folder / "silence.wav"
    path.write_bytes(encode_wav(np.zeros((8000, 1), np.int16), 16000))
    return path


def pipeline_yaml(folder: Path, detector: str, llm: str, asr: str,
                  extra: dict[str, Any] | None = None) -> Path:
    config: dict[str, Any] = {
        "endpoints": {"detector": {"address": detector, "deadline_ms": 5000},
                      "llm": {"address": llm, "deadline_ms": 30000},
                      "asr": {"address": asr, "deadline_ms": 30000}},
        "routes": {
            "people": {
                "input": {"url": str(one_frame_video(folder)), "fps": 2, "loop": True},
                "call": {"service": "detector", "method": "Detect", "labels": ["person"],
                         "min_score": 0.6},
                "post": [{"track": {"labels": ["person"], "min_hits": 1, "max_age_s": 2}},
                         {"count": {"label": "person", "into": "count"}}],
                "outputs": [{"product": "people_count", "from": "count", "max_age_s": 5}]},
            "hear": {
                "input": {"audio": str(silent_wav(folder))},
                "call": {"service": "asr", "method": "Transcribe", "language": "en"},
                "outputs": [{"product": "transcript", "from": "transcript",
                             "max_age_s": 30}]},
            "ask": {
                "input": {"product": "transcript"},
                "call": {"service": "llm", "method": "Generate", "prompt": "{value}",
                         "max_tokens": 32,
                         "context": {"products": ["people_count"], "stale": "omit"}},
                "outputs": [{"jsonl": str(folder / "answers.jsonl"), "from": "answer"}]},
        },
        "agent": {
            "audit": str(folder / "audit.jsonl"),
            "targets": {
                "cmd_vel": {"topic": TWIST_TOPIC, "type": "geometry_msgs/Twist",
                            "bounds": {"linear.x": [-0.3, 0.3], "angular.z": [-0.5, 0.5]},
                            "beyond_bounds": "clamp", "max_rate_hz": 2, "deadman_ms": 400},
                "arm": {"topic": ARM_TOPIC, "type": "std_msgs/Float64",
                        "bounds": {"data": [0.0, 1.0]}, "max_rate_hz": 10,
                        "approval": "elicit"}}},
    }
    if extra:
        config.update(extra)
    path = folder / "agent_pipeline.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


class RosListener:
    """A plain rclpy node subscribing to the policy's topics, as a robot's driver would."""

    def __init__(self) -> None:
        import rclpy
        from geometry_msgs.msg import Twist
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from std_msgs.msg import Float64

        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node("agent_test_driver", context=self.context)
        self.twists: queue.Queue[Any] = queue.Queue()
        self.arm: queue.Queue[Any] = queue.Queue()
        self.node.create_subscription(Twist, TWIST_TOPIC, self.twists.put, 10)
        self.node.create_subscription(Float64, ARM_TOPIC, self.arm.put, 10)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except Exception:
                return

    def wait_publisher(self, topic: str, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while self.node.count_publishers(topic) == 0:
            if time.monotonic() > deadline:
                raise TimeoutError(f"no publisher on {topic}")
            time.sleep(0.05)

    def drain(self) -> None:
        for q in (self.twists, self.arm):
            while not q.empty():
                q.get_nowait()

    def close(self) -> None:
        import rclpy

        rclpy.try_shutdown(context=self.context)
        self.thread.join(5)
        self.executor.shutdown()
        self.node.destroy_node()


@contextmanager
def ros_listener() -> Iterator[RosListener]:
    listener = RosListener()
    try:
        yield listener
    finally:
        listener.close()
