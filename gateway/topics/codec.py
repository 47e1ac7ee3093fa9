"""Topic messages <-> route values, without ROS: one entry per ROS message type the gateway
reads or writes (TYPES), used by the ROS node (oricf.gateway.ros) and by recordings
(oricf.gateway.recording) alike.

An entry says how a message of its type becomes an input record, and how a route value
becomes the message's fields (`fields`: a mapping by the ROS field names, nested messages
as mappings). From those fields cdr.write serializes the message for recordings, and the
ROS node fills its rclpy message (oricf.gateway.ros.messages), so both write the same
message. Camera frames are read from their serialized bytes (cdr.py); text, numbers and
audio from the `data` field of a decoded message, rclpy's or mcap-ros2-support's alike.

Audio convention: std_msgs/Int16MultiArray, one complete utterance per message, int16 PCM
samples interleaved by channel; the sample rate and channel count come from the route's YAML
(16000 Hz mono by default), `layout` is ignored. Audio the gateway publishes (speech) follows
the default: 16000 Hz mono, one sentence per message.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.config import InputConfig
from oricf.gateway.route import Loader
from oricf.gateway.topics import cdr
from oricf.gateway.values import (
    FRAME_TIME,
    AudioClip,
    Frame,
    Record,
    audio_clip,
    compressed_frame,
    raw_frame,
)
from oricf.imaging import RAW_CHANNELS, Detection, encode_image

Fields = dict[str, Any]
# A route value and the input frame's header (None without one) -> the message's fields.
ToFields = Callable[[Any, "cdr.Stamp | None"], Fields]


@dataclass(frozen=True)
class TopicType:
    """One ROS message type. `read`: its serialized bytes -> the input record, for the types
    taken serialized (camera frames; the others are read from their decoded `data` by
    data_record). `depth`: how many messages its publisher keeps for a slow subscriber."""

    name: str
    fields: ToFields
    read: Callable[[bytes], Record] | None = None
    depth: int = 10


def read_image(serialized: bytes) -> Record:
    image = cdr.image(serialized)
    frame = raw_frame(image.data, image.encoding, image.width, image.height, image.step)
    return {"image": frame, "header": image.header}


def read_compressed_image(serialized: bytes) -> Record:
    compressed = cdr.compressed_image(serialized)
    return {"image": compressed_frame(compressed.data, compressed.format),
            "header": compressed.header}


def _header(header: cdr.Stamp | None) -> Fields:
    return {} if header is None else {"header": cdr.header(header)}


def _frame(value: Any) -> Frame:
    if not isinstance(value, Frame):
        raise TypeError(f"{type(value).__name__} is not an image")
    return value


def image_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    """The input frame's header, so the annotation lines up with it."""
    frame = _frame(value).as_raw()  # an encoded annotation from the service is decoded
    return {**_header(header), "height": frame.height, "width": frame.width,
            "encoding": frame.encoding, "is_bigendian": 0,
            "step": frame.width * RAW_CHANNELS[frame.encoding], "data": frame.data}


def compressed_image_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    frame = _frame(value)
    if frame.encoding in RAW_CHANNELS:
        frame = Frame(encode_image(frame.pixels(), "jpeg"), "jpeg")
    return {**_header(header), "format": frame.encoding, "data": frame.data}


def audio_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    return {"data": np.frombuffer(topic_audio(value), "<i2")}


def detection_array_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    """Each detection with the array's header, as vision_msgs/Detection2D: its box as centre
    and size, one hypothesis (class, score) and its track id as `id` (empty untracked)."""
    stamp = _header(header)
    return {**stamp, "detections": [{**stamp, **detection_fields(d)} for d in value]}


def detection_fields(detection: Detection) -> Fields:
    if not isinstance(detection, Detection):
        raise TypeError(f"{type(detection).__name__} is not a detection")
    b = detection.box
    return {"id": "" if detection.track_id is None else str(detection.track_id),
            "results": [{"hypothesis": {"class_id": detection.label,
                                        "score": float(detection.score)}}],
            "bbox": {"center": {"position": {"x": float(b.x_min + b.x_max) / 2,
                                             "y": float(b.y_min + b.y_max) / 2}},
                     "size_x": float(b.x_max - b.x_min), "size_y": float(b.y_max - b.y_min)}}


TYPES: dict[str, TopicType] = {t.name: t for t in [
    # depth 1: a subscriber that falls behind gets the newest frame, not a backlog
    TopicType("sensor_msgs/Image", image_fields, read_image, depth=1),
    TopicType("sensor_msgs/CompressedImage", compressed_image_fields, read_compressed_image,
              depth=1),
    TopicType("std_msgs/String", lambda value, _: {"data": str(value)}),
    TopicType("std_msgs/Int32", lambda value, _: {"data": int(value)}),
    TopicType("std_msgs/Int16MultiArray", audio_fields),
    TopicType("vision_msgs/Detection2DArray", detection_array_fields),
]}


def topic_type(name: str) -> TopicType:
    """The entry of a type (InvalidInput for a type the gateway does not read or write)."""
    try:
        return TYPES[name]
    except KeyError:
        raise InvalidInput(f"unsupported message type {name}") from None


def message_fields(type_: str, value: Any, header: cdr.Stamp | None = None) -> Fields:
    """A route value -> the fields of an output message of the given type (raises TypeError
    or ValueError for a value that does not fit, InvalidInput for a type without an entry)."""
    return topic_type(type_).fields(value, header)


def serialize(type_: str, value: Any, header: cdr.Stamp | None = None) -> bytes:
    """A route value -> the serialized output message of the given type (raises as
    message_fields, and ValueError for a number that does not fit its field)."""
    return cdr.write(type_, message_fields(type_, value, header))


def image_record(type_: str, serialized: bytes) -> Record:
    """One serialized camera message -> the route's input record (raises InvalidInput);
    FRAME_TIME is the header's stamp, unless the camera left it zero."""
    read = topic_type(type_).read
    if read is None:
        raise InvalidInput(f"{type_} is not a camera frame")
    record = read(serialized)
    stamp = record["header"]
    if stamp.sec or stamp.nanosec:
        record[FRAME_TIME] = stamp.sec + stamp.nanosec / 1e9
    return record


def image_loader(type_: str, serialized: bytes) -> Loader:
    """A camera frame, read when the route takes it (a frame dropped is never read)."""
    return lambda: image_record(type_, serialized)


def timed(load: Loader, fallback_ns: int) -> Loader:
    """A camera frame's loader whose record has FRAME_TIME: its stamp, or `fallback_ns` (when
    it arrived, or was recorded) for a camera that does not stamp its frames."""

    def load_timed() -> Record:
        record = load()
        record.setdefault(FRAME_TIME, fallback_ns / 1e9)
        return record

    return load_timed


def data_record(config: InputConfig, data: Any) -> Record:
    """The `data` of a text, number or audio message -> the route's input record."""
    field = config.field
    if field == "audio":
        return {"audio": audio_clip(np.asarray(data, dtype=np.int16), config.sample_rate,
                                    config.channels)}
    if field in ("text", "value"):
        return {field: data}
    raise InvalidInput(f"unsupported message type {config.type}")


def data_loader(config: InputConfig, data: Any) -> Loader:
    """A text, number or audio message, read when the route takes it."""
    return lambda: data_record(config, data)


TOPIC_AUDIO_RATE = 16000  # the convention's default: what a subscriber assumes


def topic_audio(value: Any) -> bytes:
    """Audio for an std_msgs/Int16MultiArray topic: mono little-endian int16 at
    TOPIC_AUDIO_RATE (raises TypeError for a value that is no audio)."""
    if not isinstance(value, AudioClip):
        raise TypeError(f"{type(value).__name__} is not audio")
    return value.mono(TOPIC_AUDIO_RATE).astype("<i2").tobytes()
