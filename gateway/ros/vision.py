"""Detections as vision_msgs/Detection2DArray, the message ROS perception tools consume
(yolo_ros, Isaac ROS, the OpenVINO toolkit's nodes, RViz and Foxglove panels).

vision_msgs is not among the ROS packages on PyPI: a robot has it from its ROS install
(`apt install ros-jazzy-vision-msgs`). It is imported only when a pipeline has such an
output, and a pipeline that asks for it where it cannot be imported is refused at start,
saying so. Each detection becomes a Detection2D (oricf.gateway.topics.codec): its box as
centre and size in pixels, one hypothesis (class name, score), and its track id as the
message's `id` (vision_msgs: "the same object in different detection messages has the same
id"; empty when not tracked).
"""

from __future__ import annotations

import importlib
from typing import Any

from oricf.errors import ConfigError

DETECTION_ARRAY = "vision_msgs/Detection2DArray"
INSTALL_HINT = ("install the vision_msgs package of your ROS distribution "
                "(e.g. apt install ros-jazzy-vision-msgs) and source its setup")


def vision_msgs() -> Any:
    """The vision_msgs.msg module, or ConfigError naming what to install."""
    try:
        return importlib.import_module("vision_msgs.msg")
    except ImportError as exc:
        raise ConfigError(f"an output of type {DETECTION_ARRAY} needs the ROS package "
                          f"vision_msgs, which cannot be imported here ({exc}): "
                          f"{INSTALL_HINT}") from None
