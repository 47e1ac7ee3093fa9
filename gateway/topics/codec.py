"""Topic messages <-> route records, without ROS, through the table of types
(oricf.gateway.topics.types): the ROS node (oricf.gateway.ros) and recordings
(oricf.gateway.recording) make input records and output messages here alike.

An input message, in the form its type is taken (serialized for camera frames, else decoded:
rclpy's message or mcap-ros2-support's), becomes the record field its type fills, with its
header where it has one; an output value becomes its message's fields, which cdr.write
serializes for recordings and the ROS node fills into its rclpy message
(oricf.gateway.ros.messages), so both write the same message.
"""

from __future__ import annotations

from typing import Any

from oricf.errors import InvalidInput
from oricf.gateway.items import Loader
from oricf.gateway.topics import cdr
from oricf.gateway.topics.convert import Fields, stamp
from oricf.gateway.topics.types import ros_type
from oricf.gateway.values import FRAME_TIME, Record, audio_clip

DEFAULT_RATE, DEFAULT_CHANNELS = 16000, 1  # a topic input's audio unless its YAML says


def input_record(type_: str, message: Any, sample_rate: int = DEFAULT_RATE,
                 channels: int = DEFAULT_CHANNELS) -> Record:
    """One input message -> the route's input record (raises InvalidInput); a message with
    a header passes it on, and FRAME_TIME is its stamp, unless the sender left it zero.
    `sample_rate` and `channels` say what an audio message's samples are."""
    entry = ros_type(type_)
    if entry.field is None or entry.read is None:
        raise InvalidInput(f"unsupported message type {type_}")
    decoded = entry.decoded(message)
    value = entry.read(decoded)
    if entry.field == "audio":
        value = audio_clip(value, sample_rate, channels)
    record: Record = {entry.field: value}
    header = getattr(decoded, "header", None)
    if header is not None:
        record["header"] = stamped = stamp(header)
        if stamped.sec or stamped.nanosec:
            record[FRAME_TIME] = stamped.sec + stamped.nanosec / 1e9
    return record


def input_loader(type_: str, message: Any, sample_rate: int = DEFAULT_RATE,
                 channels: int = DEFAULT_CHANNELS) -> Loader:
    """One input message, read when the route takes it (a message dropped is never read)."""
    return lambda: input_record(type_, message, sample_rate, channels)


def timed(load: Loader, fallback_ns: int) -> Loader:
    """A camera frame's loader whose record has FRAME_TIME: its stamp, or `fallback_ns` (when
    it arrived, or was recorded) for a camera that does not stamp its frames."""

    def load_timed() -> Record:
        record = load()
        record.setdefault(FRAME_TIME, fallback_ns / 1e9)
        return record

    return load_timed


def message_fields(type_: str, value: Any, header: cdr.Stamp | None = None) -> Fields:
    """A value -> the fields of a message of the given type (raises TypeError or ValueError
    for a value that does not fit, InvalidInput for a type the gateway does not write)."""
    write = ros_type(type_).write
    if write is None:
        raise InvalidInput(f"the gateway does not write {type_}")
    return write(value, header)


def serialize(type_: str, value: Any, header: cdr.Stamp | None = None) -> bytes:
    """A value -> the serialized message of the given type (raises as message_fields, and
    ValueError for a number that does not fit its field)."""
    return cdr.write(type_, message_fields(type_, value, header))
