"""What each ROS message type's messages hold as ORICF values, both ways: `read` functions
take a decoded message (rclpy's, mcap-ros2-support's, or the fields cdr.py reads from the
serialized bytes: anything with the message's fields as attributes) to a value; `write`
functions take a value to the message's fields by name, nested messages as mappings, from
which cdr.write serializes it for recordings and the ROS node fills its rclpy message
(oricf.gateway.ros.messages). The table of types (oricf.gateway.topics.types) names them.

Images are read one way, whatever form they came in (`image_frame`, `compressed_frame_of`):
checked (sizes, encoding), not decoded.

Audio convention: std_msgs/Int16MultiArray, one complete utterance per message, int16 PCM
samples interleaved by channel; the sample rate and channel count come from the route's YAML
(16000 Hz mono by default), `layout` is ignored. Audio the gateway publishes (speech) follows
the default: 16000 Hz mono, one sentence per message.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from oricf.gateway.topics import cdr
from oricf.gateway.values import AudioClip, Frame, compressed_frame, raw_frame
from oricf.imaging import RAW_CHANNELS, Detection, encode_image

Fields = dict[str, Any]
# A value and the input frame's header (None without one) -> the message's fields.
Write = Callable[[Any, "cdr.Stamp | None"], Fields]
Read = Callable[[Any], Any]  # a decoded message -> its value

TOPIC_AUDIO_RATE = 16000  # the convention's default: what a subscriber assumes


@dataclass(frozen=True)
class JointStates:
    """A sensor_msgs/JointState as values: the joints' names and, per field, one value a
    joint (a driver may leave a field empty)."""

    names: list[str]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


@dataclass(frozen=True)
class Action:
    """One action a control loop sends: its values and, where the target names them, the
    name of each (a joint, or a field such as linear.x), and how far ahead it is meant."""

    values: list[float]
    names: list[str] | None = None
    time_from_start_s: float = 0.0


def stamp(header: Any) -> cdr.Stamp:
    """A message's header, as cdr.py reads it or as a decoded std_msgs/Header."""
    if isinstance(header, cdr.Stamp):
        return header
    return cdr.Stamp(int(header.stamp.sec), int(header.stamp.nanosec), str(header.frame_id))


def header_fields(header: cdr.Stamp | None) -> Fields:
    return {} if header is None else {"header": cdr.header(header)}


def image_frame(msg: Any) -> Frame:
    """A sensor_msgs/Image as the frame it carries, refusing one that cannot be an image."""
    return raw_frame(bytes(msg.data), str(msg.encoding), int(msg.width), int(msg.height),
                     int(msg.step))


def compressed_frame_of(msg: Any) -> Frame:
    """A sensor_msgs/CompressedImage as the frame it carries."""
    return compressed_frame(bytes(msg.data), str(msg.format))


def _frame(value: Any) -> Frame:
    if not isinstance(value, Frame):
        raise TypeError(f"{type(value).__name__} is not an image")
    return value


def image_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    """The input frame's header, so the annotation lines up with it."""
    frame = _frame(value).as_raw()  # an encoded annotation from the service is decoded
    return {**header_fields(header), "height": frame.height, "width": frame.width,
            "encoding": frame.encoding, "is_bigendian": 0,
            "step": frame.width * RAW_CHANNELS[frame.encoding], "data": frame.data}


def compressed_image_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    frame = _frame(value)
    if frame.encoding in RAW_CHANNELS:
        frame = Frame(encode_image(frame.pixels(), "jpeg"), "jpeg")
    return {**header_fields(header), "format": frame.encoding, "data": frame.data}


def data(msg: Any) -> Any:
    """The `data` field of a message as it came (text, a number)."""
    return msg.data


def samples(msg: Any) -> np.ndarray:
    """An audio message's int16 samples (the route's settings say their rate)."""
    return np.asarray(msg.data, dtype=np.int16)


def topic_audio(value: Any) -> bytes:
    """Audio for an std_msgs/Int16MultiArray topic: mono little-endian int16 at
    TOPIC_AUDIO_RATE (raises TypeError for a value that is no audio)."""
    if not isinstance(value, AudioClip):
        raise TypeError(f"{type(value).__name__} is not audio")
    return value.mono(TOPIC_AUDIO_RATE).astype("<i2").tobytes()


def audio_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    return {"data": np.frombuffer(topic_audio(value), "<i2")}


def text_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    return {"data": str(value)}


def int_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    return {"data": int(value)}


def detection_array_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    """Each detection with the array's header, as vision_msgs/Detection2D: its box as centre
    and size, one hypothesis (class, score) and its track id as `id` (empty untracked)."""
    stamped = header_fields(header)
    return {**stamped, "detections": [{**stamped, **detection_fields(d)} for d in value]}


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


def joint_states(msg: Any) -> JointStates:
    return JointStates(list(msg.name), *(np.asarray(getattr(msg, field), np.float64)
                                         for field in ("position", "velocity", "effort")))


def float_array(msg: Any) -> np.ndarray:
    return np.asarray(msg.data, np.float64)


def float_array_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    """An action, or any sequence of numbers, as a Float64MultiArray's data."""
    values = value.values if isinstance(value, Action) else value
    return {"data": [float(v) for v in values]}


def trajectory_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    """An action as one point of a JointTrajectory: its joints' positions."""
    action = _action(value)
    seconds, rest = divmod(action.time_from_start_s, 1)
    return {"joint_names": list(action.names or ()),
            "points": [{"positions": list(action.values),
                        "time_from_start": {"sec": int(seconds),
                                            "nanosec": round(rest * 1e9)}}]}


def flat_fields(value: Any, header: cdr.Stamp | None) -> Fields:
    """Fields by their dotted names ({"linear.x": 0.2}, or an action whose names are
    those) -> nested fields; the fields not given keep their defaults (zero)."""
    if isinstance(value, Action):
        value = dict(zip(value.names or (), value.values, strict=True))
    return nested(value)


def nested(flat: Mapping[str, Any]) -> Fields:
    """{"linear.x": 0.2} -> {"linear": {"x": 0.2}}."""
    out: Fields = {}
    for name, item in flat.items():
        *parents, leaf = name.split(".")
        node = out
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = item
    return out


def _action(value: Any) -> Action:
    if not isinstance(value, Action):
        raise TypeError(f"{type(value).__name__} is not an action")
    return value
