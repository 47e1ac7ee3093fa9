"""The demo's ROS 2 side: a node that publishes a camera source on camera/image_raw,
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

from oricf.gateway.config import InputConfig
from oricf.gateway.ros.dds import use_dds_profile
from oricf.gateway.sources.video_source import VideoSource, is_live

log = logging.getLogger(__name__)

CAMERA, AUDIO, QUESTION = "camera/image_raw", "/audio/utterance", "/question"
COUNT, TRANSCRIPT, ANSWER = "/human_counter", "/speech/transcript", "/answer"
SPOKEN = "/answer/audio"  # the answers' speech (oricf.demo.speech), when the demo speaks


@dataclass(frozen=True)
class Received:
    value: Any
    at: float  # time.monotonic() on arrival


class CameraFeed:
    """Publishes the frames of a camera source (a video file at its own frame rate, looped;
    an RTSP or HTTP stream or a /dev/videoN device as fast as it sends) until stopped or
    max_frames were sent; remembers when each frame left. Reads with the gateway's own video
    source, so streams reconnect the same way."""

    def __init__(self, publish: Any, source: str, max_frames: int | None) -> None:
        self.source = source
        self.fps = None if is_live(source) else _file_fps(source)
        self.publish = publish
        self.max_frames = max_frames
        self.sent_at: list[float] = []
        self._reader = VideoSource("camera", InputConfig(url=source, fps=self.fps, loop=True),
                                   self._send, lambda route: None)

    def start(self) -> None:
        self._reader.start()

    def _send(self, load: Any) -> None:
        if self.max_frames is not None and len(self.sent_at) >= self.max_frames:
            return
        frame = load()["image"]
        message = image_from_pixels(frame.pixels(), "bgr8")
        self.sent_at.append(time.monotonic())
        self.publish(message)

    def last_sent_before(self, moment: float) -> float | None:
        index = bisect.bisect_right(self.sent_at, moment)
        return self.sent_at[index - 1] if index else None

    def stop(self) -> None:
        self._reader.stop()


def image_from_pixels(pixels: np.ndarray, encoding: str = "bgr8") -> Image:
    """A sensor_msgs/Image from a uint8 array, as a camera driver publishes it (the demo's
    camera, and other publishers of camera frames in the smoke check, tests and benchmarks)."""
    height, width = pixels.shape[:2]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    msg = Image(height=height, width=width, encoding=encoding, is_bigendian=0,
                step=width * channels)
    msg.data = np.ascontiguousarray(pixels).tobytes()
    return msg


def _file_fps(path: str) -> float:
    import cv2

    capture = cv2.VideoCapture(str(Path(path).expanduser()))
    if not capture.isOpened():
        raise RuntimeError(f"cannot open video {path}")
    fps = capture.get(cv2.CAP_PROP_FPS)
    capture.release()
    return fps if fps and fps > 0 else 10.0


class DemoNode:
    """Publishers for the pipeline's inputs, a queue of timestamped messages per output."""

    def __init__(self, context: Context) -> None:
        self.node = Node("oricf_demo", context=context)
        self.outputs: dict[str, queue.Queue[Received]] = {}
        self.counts: list[Received] = []
        self.on_spoken: Any = None  # called with each piece of speech as it arrives
        for topic, kind in ((COUNT, Int32), (TRANSCRIPT, String), (ANSWER, String),
                            (SPOKEN, Int16MultiArray)):
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
            if topic == SPOKEN and self.on_spoken is not None:
                self.on_spoken(msg.data)
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
