"""topic: {topic: /human_counter, type: TYPE, from: count} publishes on a ROS topic, in a
type the table of types lets outputs name (oricf.gateway.topics.types). The ROS node's
publishers (oricf.gateway.ros.publishers) or, in a replay, the recording
(oricf.gateway.recording.recorder.TopicOutputs) send it; each converts the value to the
topic's message through the topic codec (oricf.gateway.topics.codec)."""

from __future__ import annotations

from typing import Any

from pydantic import Field, field_validator

from oricf.config import Schema
from oricf.gateway.components import ComponentContext, Sink, SinkKind
from oricf.gateway.topics import types
from oricf.gateway.values import Record


class TopicOutput(Schema):
    topic: str | None = None
    type: str | None = Field(None, description="the message type: a topic output type of "
                             "oricf.gateway.topics.types")

    @field_validator("type")
    @classmethod
    def _known(cls, type_: str | None) -> str | None:
        return None if type_ is None else types.check(type_, "output", "a topic output type")


def check(output: Any) -> None:
    if output.type is None:
        raise ValueError("type: required with topic")


class RosOutputs(Sink):
    """Topic outputs to the ROS side, which a pipeline without ROS does not have."""

    def __init__(self, context: ComponentContext) -> None:
        self._ros = context.ros

    def send(self, output: Any, value: Any, record: Record) -> None:
        if self._ros is None:
            raise RuntimeError(f"output topic {output.topic} needs the ROS node")
        self._ros.emit(output, value, record)

    def close(self) -> None:
        """The ROS side closes its own publishers."""


def open_outputs(context: ComponentContext) -> Sink:
    return RosOutputs(context)


COMPONENT = SinkKind("topic", TopicOutput, open_outputs, check, ros=True, rank=0)
