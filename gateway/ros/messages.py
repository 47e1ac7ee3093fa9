"""ROS messages <-> route values, with rclpy's message types.

Incoming messages become loaders: conversion runs when the route takes the message, so a
queued message that is dropped is never converted. Camera frames arrive serialized and are
read by oricf.gateway.recording.cdr; the other inputs arrive as rclpy messages. What a
message turns into is decided in oricf.gateway.recording.topic_values, which recordings
share without ROS.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header, Int16MultiArray, Int32, String

from oricf.errors import InvalidInput
from oricf.gateway.config import InputConfig
from oricf.gateway.recording import cdr
from oricf.gateway.recording.topic_values import data_record, image_record, topic_audio
from oricf.gateway.ros import vision
from oricf.gateway.route import Loader
from oricf.gateway.values import Frame, Record
from oricf.imaging import RAW_CHANNELS

MESSAGE_TYPES: dict[str, Any] = {
    "sensor_msgs/Image": Image,
    "sensor_msgs/CompressedImage": CompressedImage,
    "std_msgs/String": String,
    "std_msgs/Int16MultiArray": Int16MultiArray,
    "std_msgs/Int32": Int32,
}


def image_loader(type_: str, serialized: bytes) -> Loader:
    return lambda: image_record(type_, serialized)


def to_record(config: InputConfig, msg: Any) -> Record:
    """One incoming message (not a camera frame) -> the route's input record."""
    return data_record(config, msg.data)


def loader(config: InputConfig, msg: Any) -> Loader:
    return lambda: to_record(config, msg)


def message_type(type_: str) -> Any:
    """The rclpy message class of a topic type (vision_msgs imported only when asked for,
    ConfigError if it cannot be)."""
    if type_ == vision.DETECTION_ARRAY:
        return vision.vision_msgs().Detection2DArray
    return MESSAGE_TYPES[type_]


def to_message(type_: str, value: Any, header: cdr.Stamp | None = None) -> Any:
    """A route value -> the output message of the given type."""
    if type_ == vision.DETECTION_ARRAY:
        return vision.detection_array(value, header and ros_header(header))
    if type_ == "std_msgs/Int32":
        return Int32(data=int(value))
    if type_ == "std_msgs/String":
        return String(data=str(value))
    if type_ == "sensor_msgs/Image":
        return image_message(value, header)
    if type_ == "std_msgs/Int16MultiArray":
        message = Int16MultiArray()
        message.data = np.frombuffer(topic_audio(value), "<i2")
        return message
    raise InvalidInput(f"unsupported output type {type_}")


def image_message(frame: Frame, header: cdr.Stamp | None = None) -> Image:
    frame = frame.as_raw()  # an encoded annotation from the service is decoded
    msg = Image(height=frame.height, width=frame.width, encoding=frame.encoding,
                is_bigendian=0, step=frame.width * RAW_CHANNELS[frame.encoding])
    if header is not None:  # the input frame's, so the annotation lines up with it
        msg.header = ros_header(header)
    msg.data = frame.data
    return msg


def ros_header(header: cdr.Stamp) -> Header:
    return Header(stamp=Time(sec=header.sec, nanosec=header.nanosec), frame_id=header.frame_id)
