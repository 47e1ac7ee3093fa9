"""Detections as vision_msgs/Detection2DArray, the message ROS perception tools consume
(yolo_ros, Isaac ROS, the OpenVINO toolkit's nodes, RViz and Foxglove panels).

vision_msgs is not among the ROS packages on PyPI: a robot has it from its ROS install
(`apt install ros-jazzy-vision-msgs`). It is imported only when a pipeline has such an
output, and a pipeline that asks for it where it cannot be imported is refused at start,
saying so. Each detection becomes a Detection2D: its box as centre and size in pixels, one
hypothesis (class name, score), and its track id as the message's `id` (vision_msgs: "the
same object in different detection messages has the same id"; empty when not tracked).
"""

from __future__ import annotations

import importlib
from typing import Any

from oricf.errors import ConfigError
from oricf.gateway.recording.topic_values import box_fields
from oricf.imaging import Detection

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


def detection_array(detections: list[Detection], header: Any | None = None) -> Any:
    """A route's detections -> vision_msgs/Detection2DArray (header: the input frame's)."""
    msgs = vision_msgs()
    array = msgs.Detection2DArray()
    if header is not None:
        array.header = header
    for fields in map(box_fields, detections):  # the fields a recording writes, too
        item = msgs.Detection2D()
        item.header = array.header
        item.id = fields.id
        item.bbox.center.position.x = fields.center_x
        item.bbox.center.position.y = fields.center_y
        item.bbox.size_x = fields.size_x
        item.bbox.size_y = fields.size_y
        hypothesis = msgs.ObjectHypothesisWithPose()
        hypothesis.hypothesis.class_id = fields.class_id
        hypothesis.hypothesis.score = fields.score
        item.results = [hypothesis]
        array.detections.append(item)
    return array
