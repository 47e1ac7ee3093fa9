"""Real DDS for gateway tests: a private domain, an in-process gateway, a probe node.

Each test session picks a random ROS_DOMAIN_ID and keeps discovery on localhost, so
parallel runs on one machine never see each other's topics.
"""

from __future__ import annotations

import logging
import queue
import random
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Int16MultiArray, Int32, String

from oricf.demo.node import image_from_pixels
from oricf.gateway.config import PipelineConfig
from oricf.gateway.ros.dds import dds_profile
from oricf.gateway.shells.ros_node import GatewayNode

OUTPUTS = {"/human_counter": Int32, "/answer": String, "/speech/transcript": String,
           "/camera/image_annotated": Image, "/people_fallen": Int32, "/fall_alert": String}


def private_domain() -> dict[str, str]:
    """Environment for a DDS domain nobody else on this machine uses, with the Fast DDS
    profile that lets raw camera frames cross processes (see the XML file)."""
    return {"ROS_DOMAIN_ID": str(random.randint(1, 100)),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "FASTRTPS_DEFAULT_PROFILES_FILE": str(dds_profile())}


class Probe:
    """A test node: publishes inputs, collects every output message in a queue per topic."""

    def __init__(self, context: Context) -> None:
        self.node = Node("gateway_test_probe", context=context)
        self.received: dict[str, queue.Queue[Any]] = {}
        for topic, kind in OUTPUTS.items():
            self.received[topic] = queue.Queue()
            self.node.create_subscription(kind, topic, self._collector(topic), 10)
        self.camera = self.node.create_publisher(Image, "camera/image_raw",
                                                 qos_profile_sensor_data)
        self.audio = self.node.create_publisher(Int16MultiArray, "/audio/utterance",
                                                QoSProfile(depth=10))
        self.question = self.node.create_publisher(String, "/question", QoSProfile(depth=10))
        self.compressed = self.node.create_publisher(CompressedImage, "camera/compressed",
                                                     qos_profile_sensor_data)

    def _collector(self, topic: str) -> Any:
        return lambda msg: self.received[topic].put(msg)

    def wait_connected(self, inputs: tuple[str, ...] = ("camera/image_raw",
                                                        "/audio/utterance", "/question"),
                       timeout: float = 10.0, output: str = "/human_counter") -> None:
        """Until the gateway's subscriptions to these inputs and its output are discovered."""
        by_topic = {"camera/image_raw": self.camera, "/audio/utterance": self.audio,
                    "/question": self.question, "camera/compressed": self.compressed}
        publishers = [by_topic[topic] for topic in inputs]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in publishers) and \
                    self.node.count_publishers(output) > 0:
                return
            time.sleep(0.05)
        raise TimeoutError("the gateway's topics were not discovered")

    def warm_up(self, pixels: np.ndarray, timeout: float = 20.0) -> None:
        """Publishes a frame until a count comes back: discovery is complete both ways
        (a best-effort message sent before the other side has matched is simply lost)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.publish_frame(pixels)
            try:
                self.next("/human_counter", timeout=0.5)
            except queue.Empty:
                continue
            time.sleep(0.5)  # let late answers to the repeats arrive, then forget them
            self.drain("/human_counter")
            return
        raise TimeoutError("no count came back from the gateway")

    def publish_frame(self, pixels: np.ndarray, encoding: str = "bgr8", frame_id: str = "",
                      stamp_s: int = 0) -> None:
        msg = image_from_pixels(pixels, encoding)
        msg.header.frame_id, msg.header.stamp.sec = frame_id, stamp_s
        self.camera.publish(msg)

    def publish_audio(self, samples: np.ndarray) -> None:
        msg = Int16MultiArray()
        msg.data = samples.astype(np.int16)
        self.audio.publish(msg)

    def next(self, topic: str, timeout: float) -> Any:
        return self.received[topic].get(timeout=timeout)

    def drain(self, topic: str) -> list[Any]:
        items = []
        while not self.received[topic].empty():
            items.append(self.received[topic].get_nowait())
        return items


@contextmanager
def spinning(context: Context, *nodes: Node) -> Iterator[MultiThreadedExecutor]:
    """An executor spinning the nodes in a background thread until the block ends."""
    executor = MultiThreadedExecutor(num_threads=len(nodes) + 4, context=context)
    for node in nodes:
        executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        yield executor
    finally:
        executor.shutdown(timeout_sec=5)
        spinner.join(timeout=5)


@contextmanager
def running_probe(context: Context) -> Iterator[Probe]:
    """A probe node alone (the gateway runs elsewhere, e.g. as a child process)."""
    probe = Probe(context)
    try:
        with spinning(context, probe.node):
            yield probe
    finally:
        probe.node.destroy_node()


@contextmanager
def running_gateway(config: PipelineConfig, context: Context) -> Iterator[tuple[GatewayNode,
                                                                                  Probe]]:
    """The gateway node and a probe node in this process, on real DDS."""
    gateway = GatewayNode(config, context=context)
    gateway.configure()
    gateway.activate()
    probe = Probe(context)
    try:
        with spinning(context, gateway, probe.node):
            try:
                outputs = [o.topic for r in config.routes.values() for o in r.outputs if o.topic]
                probe.wait_connected(tuple(r.input.topic for r in config.routes.values()
                                           if r.input.topic is not None), output=outputs[0])
                yield gateway, probe
            finally:
                gateway.shutdown()
    finally:
        probe.node.destroy_node()
        gateway.destroy_node()


def wait_for(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError("condition not met in time")
        time.sleep(0.02)


def logged(caplog: pytest.LogCaptureFixture, text: str) -> Callable[[], bool]:
    return lambda: any(text in r.getMessage() and r.levelno >= logging.WARNING
                       for r in caplog.records)
