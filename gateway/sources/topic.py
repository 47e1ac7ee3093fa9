"""topic: {topic: camera/image_raw, type: TYPE} takes a ROS topic's messages, of a type
the table of types lets inputs name (oricf.gateway.topics.types). The ROS node subscribes
(oricf.gateway.shells.ros_node), or a replay reads them from a recording
(oricf.gateway.recording.replay); camera topics keep only the newest frame."""

from __future__ import annotations

from typing import Any

from pydantic import Field, field_validator

from oricf.config import Schema
from oricf.gateway.components import SourceKind
from oricf.gateway.topics import types


class TopicInput(Schema):
    topic: str | None = None
    type: str | None = Field(None, description="the message type: a topic input type of "
                             "oricf.gateway.topics.types")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str | None) -> str | None:
        return None if type_ is None else types.check(type_, "input", "a topic input type")


def check(input_config: Any) -> None:
    if input_config.type is None:
        raise ValueError("type: required with topic")
    if frames(input_config) and input_config.keep == "queue":
        raise ValueError("keep: camera inputs keep only the newest frame (latest)")


def stray(input_config: Any) -> str | None:
    if input_config.type is None:
        return None
    return "type: only with topic (the other inputs carry their own kind)"


def field(input_config: Any) -> str:
    return str(types.ros_type(str(input_config.type)).field)


def frames(input_config: Any) -> bool:
    """Camera frames: the newest only (types.RosType.frames)."""
    return types.ros_type(str(input_config.type)).frames


def more_fields(input_config: Any) -> frozenset[str]:
    """A camera frame comes with its message's header (stamp and frame), which topic
    outputs of the route can pass on."""
    return frozenset({"header"}) if field(input_config) == "image" else frozenset()


COMPONENT = SourceKind("topic", TopicInput, field, None, check, stray,
                       frames, more_fields=more_fields,
                       ros=True, rank=0)
