"""The topic codec has an entry for every topic type a pipeline may name, and each entry
works both ways: a route value written as CDR and as an rclpy message gives the same message
(rclpy reads the one as the other), and an input type's message reads back as the value it
was made from."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from oricf.gateway.ros.messages import message_type, to_message
from oricf.gateway.topics import cdr
from oricf.gateway.topics.codec import input_record, serialize
from oricf.gateway.topics.types import TYPES, names
from oricf.gateway.values import AudioClip, Frame
from oricf.imaging import Box, Detection, encode_image
from tests.support.vision_msgs import build, environment

STAMP = cdr.Stamp(1700, 5, "front_camera")
PIXELS = np.random.default_rng(3).integers(0, 255, (6, 10, 3), dtype=np.uint8)
DETECTIONS = [Detection("person", 0, 0.9, Box(1, 2, 30, 40), track_id=7),
              Detection("dog", 1, 0.25, Box(10.5, 20, 40.5, 100))]
VALUES: dict[str, Any] = {
    "sensor_msgs/Image": Frame.from_pixels(PIXELS),
    "sensor_msgs/CompressedImage": Frame(encode_image(PIXELS, "jpeg"), "jpeg"),
    "std_msgs/String": "how many people? née 😀",
    "std_msgs/Int32": -5,
    "std_msgs/Int16MultiArray": AudioClip(np.arange(-800, 800, 7, dtype="<i2").tobytes(),
                                          16000, 1),
    "vision_msgs/Detection2DArray": DETECTIONS,
}
VISION = "vision_msgs/Detection2DArray"
TOPIC_TYPES = sorted(set(names("input")) | set(names("output")))


def test_every_type_a_pipeline_may_name_has_an_entry() -> None:
    assert set(TOPIC_TYPES) <= set(TYPES)
    assert set(VALUES) == set(TOPIC_TYPES)


@pytest.mark.parametrize("type_", [t for t in TOPIC_TYPES if t != VISION])
def test_a_value_written_as_cdr_is_the_message_rclpy_serializes(type_: str) -> None:
    written = serialize(type_, VALUES[type_], STAMP)
    published = to_message(type_, VALUES[type_], STAMP)
    assert deserialize_message(written, message_type(type_)) == published
    # and what rclpy serializes reads back the same (its alignment padding need not be zeros)
    assert deserialize_message(serialize_message(published), message_type(type_)) == published


@pytest.mark.parametrize("type_", names("input"))
def test_an_input_message_reads_back_as_its_value(type_: str) -> None:
    written = serialize(type_, VALUES[type_], STAMP)
    field = TYPES[type_].field
    assert field is not None
    if TYPES[type_].frames:  # camera frames: from the serialized bytes
        record = input_record(type_, written)
        assert (record[field], record["header"]) == (VALUES[type_], STAMP)
    # and every type from rclpy's message, as the node takes it
    record = input_record(type_, deserialize_message(written, message_type(type_)))
    assert record[field] == VALUES[type_]


ROUND_TRIP_VISION = """
from rclpy.serialization import deserialize_message, serialize_message
from oricf.gateway.ros.messages import message_type, to_message
from oricf.gateway.topics.codec import serialize
from tests.gateway.topics.test_codec import DETECTIONS, STAMP, VISION
written = serialize(VISION, DETECTIONS, STAMP)
published = to_message(VISION, DETECTIONS, STAMP)
assert deserialize_message(written, message_type(VISION)) == published
assert deserialize_message(serialize_message(published), message_type(VISION)) == published
assert [d.id for d in published.detections] == ["7", ""]
"""


def test_detections_written_as_cdr_are_the_message_rclpy_serializes() -> None:
    """vision_msgs is a built workspace, found through variables set before Python starts."""
    done = subprocess.run([sys.executable, "-c", ROUND_TRIP_VISION], capture_output=True,
                          text=True, env=environment(build()), timeout=120)
    assert done.returncode == 0, done.stderr
