"""topic: {topic: camera/image_raw, type: sensor_msgs/Image} takes a ROS topic's messages.
The ROS node subscribes (oricf.gateway.shells.ros_node), or a replay reads them from a recording
(oricf.gateway.recording.replay); camera topics keep only the newest frame."""

from __future__ import annotations

from typing import Any

from oricf.config import Schema
from oricf.gateway.components import SourceKind
from oricf.gateway.topics.types import IMAGE_INPUTS, INPUT_FIELDS, InputType


class TopicInput(Schema):
    topic: str | None = None
    type: InputType | None = None


def check(input_config: Any) -> None:
    if input_config.type is None:
        raise ValueError("type: required with topic")
    if input_config.type in IMAGE_INPUTS and input_config.keep == "queue":
        raise ValueError("keep: camera inputs keep only the newest frame (latest)")


def stray(input_config: Any) -> str | None:
    if input_config.type is None:
        return None
    return "type: only with topic (the other inputs carry their own kind)"


def field(input_config: Any) -> str:
    return INPUT_FIELDS[str(input_config.type)]


def more_fields(input_config: Any) -> frozenset[str]:
    """A camera frame comes with its message's header (stamp and frame), which topic
    outputs of the route can pass on."""
    return frozenset({"header"}) if field(input_config) == "image" else frozenset()


COMPONENT = SourceKind("topic", TopicInput, field, None, check, stray,
                       lambda config: config.type in IMAGE_INPUTS, more_fields=more_fields,
                       ros=True, rank=0)
