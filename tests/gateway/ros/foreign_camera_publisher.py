"""A camera node ORICF did not write: plain rclpy, no ORICF import, no ORICF settings.

Run as `python -m tests.gateway.ros.foreign_camera_publisher TOPIC VIDEO COUNT RELIABILITY
[MATCH_TIMEOUT_S]` with no FASTRTPS_DEFAULT_PROFILES_FILE: publishes COUNT raw 640x480 bgr8
frames of VIDEO at 10 fps as sensor_msgs/Image, the way common drivers do (RELIABILITY
reliable: image_transport's default, reliable with depth 10; best_effort: the sensor_data
profile, best effort with depth 5), once a subscriber has matched, cycling through the
video's first 50 frames. Prints {"published": COUNT} as JSON, or an error when no subscriber
matched within MATCH_TIMEOUT_S (default 30).
"""

from __future__ import annotations

import json
import sys
import time

import cv2
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Image

from tests.gateway.ros.matching import MATCH_TIMEOUT_S, wait_for_subscriber

WIDTH, HEIGHT = 640, 480
RATE_HZ = 10.0
DISTINCT_FRAMES = 50  # 46 MB; longer runs cycle through them
SETTLE_S = 2.0  # discovery completes both ways, and a subscriber adapting its QoS has done so


def frames(video: str, count: int) -> list[bytes]:
    capture = cv2.VideoCapture(video)
    pixels, needed = [], min(count, DISTINCT_FRAMES)
    try:
        while len(pixels) < needed:
            ok, frame = capture.read()
            if not ok:
                raise RuntimeError(f"{video}: fewer than {needed} frames")
            pixels.append(cv2.resize(frame, (WIDTH, HEIGHT)).tobytes())
    finally:
        capture.release()
    return pixels


def qos(reliability: str) -> QoSProfile:
    if reliability == "reliable":
        return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    if reliability == "best_effort":
        return qos_profile_sensor_data
    raise ValueError(f"reliability: reliable or best_effort, not {reliability!r}")


def main(topic: str, video: str, count: int, reliability: str,
         match_timeout_s: float = MATCH_TIMEOUT_S) -> int:
    pixels = frames(video, count)
    rclpy.init()
    node = Node("foreign_camera")
    publisher = node.create_publisher(Image, topic, qos(reliability))
    if not wait_for_subscriber(publisher, match_timeout_s):
        print(json.dumps({"error": "no subscriber matched"}))
        return 1
    time.sleep(SETTLE_S)
    start = time.monotonic()
    for i in range(count):
        msg = Image(height=HEIGHT, width=WIDTH, encoding="bgr8", step=WIDTH * 3)
        msg.header.frame_id = "foreign_camera"
        msg.header.stamp.sec = i
        msg.data = pixels[i % len(pixels)]
        publisher.publish(msg)
        time.sleep(max(0.0, start + (i + 1) / RATE_HZ - time.monotonic()))
    time.sleep(1.0)  # a reliable writer repairs the last frames before it leaves
    print(json.dumps({"published": count}))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4],
                  *map(float, sys.argv[5:6])))
