"""The demo's ROS 2 side: a node that replays a video on camera/image_raw at its frame rate,
publishes spoken questions on /audio/utterance (typed ones on /question), and timestamps
every output of the gateway (/human_counter, /speech/transcript, /answer) as it arrives.

Imports rclpy: load this module only when ROS 2 is wanted.
"""

from __future__ import annotations

import bisect
import logging
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Image
from std_msgs.msg import Int16MultiArray, Int32, String

from oricf.gateway.convert import image_from_pixels
from oricf.gateway.dds import use_dds_profile

log = logging.getLogger(__name__)

CAMERA, AUDIO, QUESTION = "camera/image_raw", "/audio/utterance", "/question"
COUNT, TRANSCRIPT, ANSWER = "/human_counter", "/speech/transcript", "/answer"


@dataclass(frozen=True)
class Received:
    value: Any
    at: float  # time.monotonic() on arrival


class VideoReplay:
    """Publishes the frames of a video at its own frame rate, looping, until stopped or
    max_frames were sent; remembers when each frame left."""

    def __init__(self, publish: Any, video: Path, max_frames: int | None) -> None:
        import cv2

        self.capture = cv2.VideoCapture(str(video))
        if not self.capture.isOpened():
            raise RuntimeError(f"cannot open video {video}")
        fps = self.capture.get(cv2.CAP_PROP_FPS)
        self.fps = fps if fps and fps > 0 else 10.0
        self.publish = publish
        self.max_frames = max_frames
        self.sent_at: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="video-replay", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _next_frame(self) -> np.ndarray:
        import cv2

        ok, frame = self.capture.read()
        if not ok:  # end of the video: from the start again
            self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self.capture.read()
            if not ok:
                raise RuntimeError("the video has no readable frame")
        return np.asarray(frame)

    def _run(self) -> None:
        period = 1.0 / self.fps
        next_at = time.monotonic()
        while not self._stop.is_set():
            if self.max_frames is not None and len(self.sent_at) >= self.max_frames:
                return
            message = image_from_pixels(self._next_frame(), "bgr8")
            self.sent_at.append(time.monotonic())
            self.publish(message)
            next_at += period
            self._stop.wait(max(0.0, next_at - time.monotonic()))

    def last_sent_before(self, moment: float) -> float | None:
        index = bisect.bisect_right(self.sent_at, moment)
        return self.sent_at[index - 1] if index else None

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        self.capture.release()


class DemoNode:
    """Publishers for the pipeline's inputs, a queue of timestamped messages per output."""

    def __init__(self, context: Context) -> None:
        self.node = Node("oricf_demo", context=context)
        self.outputs: dict[str, queue.Queue[Received]] = {}
        self.counts: list[Received] = []
        for topic, kind in ((COUNT, Int32), (TRANSCRIPT, String), (ANSWER, String)):
            self.outputs[topic] = queue.Queue()
            self.node.create_subscription(kind, topic, self._collector(topic), 10)
        self.camera = self.node.create_publisher(Image, CAMERA, qos_profile_sensor_data)
        self.audio = self.node.create_publisher(Int16MultiArray, AUDIO, QoSProfile(depth=10))
        self.question = self.node.create_publisher(String, QUESTION, QoSProfile(depth=10))
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._spinner = threading.Thread(target=self.executor.spin, name="demo-spin",
                                         daemon=True)
        self._spinner.start()

    def _collector(self, topic: str) -> Any:
        def on_message(msg: Any) -> None:
            item = Received(msg.data, time.monotonic())
            if topic == COUNT:
                self.counts.append(item)
            self.outputs[topic].put(item)
        return on_message

    def connected(self) -> bool:
        """The gateway subscribes to both inputs and publishes the outputs we wait for."""
        return (self.camera.get_subscription_count() > 0
                and self.audio.get_subscription_count() > 0
                and all(self.node.count_publishers(t) > 0 for t in (COUNT, TRANSCRIPT, ANSWER)))

    def say(self, samples: np.ndarray) -> float:
        """Publishes one utterance; returns when it left."""
        msg = Int16MultiArray()
        msg.data = samples.astype(np.int16)
        sent = time.monotonic()
        self.audio.publish(msg)
        return sent

    def type(self, text: str) -> float:
        """Publishes a typed question; returns when it left."""
        sent = time.monotonic()
        self.question.publish(String(data=text))
        return sent

    def next(self, topic: str, timeout: float) -> Received | None:
        try:
            return self.outputs[topic].get(timeout=timeout)
        except queue.Empty:
            return None

    def drain(self, topic: str) -> None:
        while not self.outputs[topic].empty():
            self.outputs[topic].get_nowait()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2)
        self._spinner.join(timeout=5)
        self.node.destroy_node()


def ros_context() -> Context:
    """An rclpy context with the Fast DDS profile that lets raw frames cross processes."""
    use_dds_profile()
    context = Context()
    rclpy.init(context=context)
    return context
