"""Topic messages <-> route values, without ROS: what the ROS node (through ros/messages.py)
and recordings (recorder.py, replay.py) share.

Camera frames are read from their serialized bytes (cdr.py); text, numbers and audio from
the `data` field of a decoded message, rclpy's or mcap-ros2-support's alike. Output values
are serialized for recordings by cdr.py, the same messages ros/messages.to_message builds.

Audio convention: std_msgs/Int16MultiArray, one complete utterance per message, int16 PCM
samples interleaved by channel; the sample rate and channel count come from the route's YAML
(16000 Hz mono by default), `layout` is ignored. Audio the gateway publishes (speech) follows
the default: 16000 Hz mono, one sentence per message.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.config import InputConfig
from oricf.gateway.recording import cdr
from oricf.gateway.route import Loader
from oricf.gateway.values import (
    FRAME_TIME,
    AudioClip,
    Frame,
    Record,
    audio_clip,
    compressed_frame,
    raw_frame,
)
from oricf.imaging import RAW_CHANNELS, Detection


def image_record(type_: str, serialized: bytes) -> Record:
    """One serialized camera message -> the route's input record (raises InvalidInput);
    FRAME_TIME is the header's stamp, unless the camera left it zero."""
    if type_ == "sensor_msgs/Image":
        image = cdr.image(serialized)
        frame = raw_frame(image.data, image.encoding, image.width, image.height, image.step)
        record: Record = {"image": frame, "header": image.header}
    else:
        compressed = cdr.compressed_image(serialized)
        record = {"image": compressed_frame(compressed.data, compressed.format),
                  "header": compressed.header}
    stamp = record["header"]
    if stamp.sec or stamp.nanosec:
        record[FRAME_TIME] = stamp.sec + stamp.nanosec / 1e9
    return record


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


TOPIC_AUDIO_RATE = 16000  # the convention's default: what a subscriber assumes


def topic_audio(value: Any) -> bytes:
    """Audio for an std_msgs/Int16MultiArray topic: mono little-endian int16 at
    TOPIC_AUDIO_RATE (raises TypeError for a value that is no audio)."""
    if not isinstance(value, AudioClip):
        raise TypeError(f"{type(value).__name__} is not audio")
    return value.mono(TOPIC_AUDIO_RATE).astype("<i2").tobytes()


def serialize_output(type_: str, value: Any, header: cdr.Stamp | None = None) -> bytes:
    """A route value -> the serialized output message of the given type (raises ValueError
    or TypeError for a value that does not fit, InvalidInput for a type without a writer)."""
    if type_ == "std_msgs/Int32":
        return cdr.write_int32(int(value))
    if type_ == "std_msgs/String":
        return cdr.write_string(str(value))
    if type_ == "std_msgs/Int16MultiArray":
        return cdr.write_int16_array(topic_audio(value))
    if type_ == "sensor_msgs/Image":
        if not isinstance(value, Frame):
            raise TypeError(f"{type(value).__name__} is not an image")
        frame = value.as_raw()
        return cdr.write_image(cdr.ImageFields(
            header or cdr.Stamp(0, 0, ""), frame.height, frame.width, frame.encoding, 0,
            frame.width * RAW_CHANNELS[frame.encoding], frame.data))
    if type_ == "vision_msgs/Detection2DArray":
        return cdr.write_detection_array(header or cdr.Stamp(0, 0, ""),
                                         [box_fields(d) for d in value])
    raise InvalidInput(f"unsupported output type {type_}")


def box_fields(detection: Detection) -> cdr.BoxFields:
    """A detection as a vision_msgs/Detection2D's fields (as oricf.gateway.ros.vision)."""
    if not isinstance(detection, Detection):
        raise TypeError(f"{type(detection).__name__} is not a detection")
    b = detection.box
    return cdr.BoxFields("" if detection.track_id is None else str(detection.track_id),
                         detection.label, float(detection.score), (b.x_min + b.x_max) / 2,
                         (b.y_min + b.y_max) / 2, b.x_max - b.x_min, b.y_max - b.y_min)
