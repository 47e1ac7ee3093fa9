"""What recordings are made of, checked against ROS itself: the message definitions table
against the installed .msg files, the complete definitions against rclpy's serializer, the
outputs written without ROS against the messages the node publishes."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Int16MultiArray, Int32, MultiArrayDimension, String

from oricf.gateway.ros import messages as convert
from oricf.gateway.topics import cdr
from oricf.gateway.topics import definitions as msgdefs
from oricf.gateway.topics.codec import serialize
from oricf.gateway.topics.types import TYPES
from oricf.gateway.values import Frame
from oricf.imaging import encode_image
from tests.support.vision_msgs import PACKAGE

VISION_MSGS = PACKAGE / "msg"


def test_the_table_has_the_fields_of_the_installed_message_files() -> None:
    for type_, fields in msgdefs.DEFINITIONS.items():
        installed = msgdefs.installed_definition(type_)
        if type_.startswith("vision_msgs/") and installed is None:  # no wheel: the copies
            kept = VISION_MSGS / f"{type_.partition('/')[2]}.msg"   # the tests build from
            assert msgdefs.fields_only(kept.read_text()) == fields, type_
            continue
        assert installed is not None, f"{type_}.msg is not installed"
        assert msgdefs.fields_only(installed) == fields, type_
        assert msgdefs.definition(type_) == installed  # comments kept, as rosbag2 keeps them


def test_a_complete_definition_is_laid_out_as_rosbag2_writes_it() -> None:
    text = msgdefs.complete_definition("sensor_msgs/Image")
    image, header, stamp = text.split("=" * 80 + "\n")
    assert image.strip() == msgdefs.definition("sensor_msgs/Image").strip()
    assert header == f"MSG: std_msgs/Header\n{msgdefs.definition('std_msgs/Header').strip()}\n"
    assert stamp.startswith("MSG: builtin_interfaces/Time\n")
    assert msgdefs.complete_definition("std_msgs/Int16MultiArray").count("MSG: ") == 2


def samples() -> list[Any]:
    image = Image(height=2, width=3, encoding="rgb8", is_bigendian=0, step=9)
    image.header.stamp.sec, image.header.frame_id = 17, "front_camera"
    image.data = bytes(range(18))
    compressed = CompressedImage(format="jpeg")
    compressed.data = b"\xff\xd8 jpeg \xff\xd9"
    audio = Int16MultiArray()
    audio.layout.dim = [MultiArrayDimension(label="samples", size=3, stride=3)]
    audio.data = [-32768, 0, 32767]
    return [image, compressed, audio, String(data="how many?"), Int32(data=-5)]


@pytest.mark.parametrize("installed", [True, False], ids=["installed", "table"])
def test_complete_definitions_decode_what_rclpy_serializes(
        installed: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    if not installed:  # as on a machine without ROS: the table alone
        monkeypatch.setattr(msgdefs, "share_dirs", list)
        monkeypatch.setattr(msgdefs, "definition", msgdefs.definition.__wrapped__)
        monkeypatch.setattr(msgdefs, "complete_definition",
                            msgdefs.complete_definition.__wrapped__)
    for msg in samples():
        type_ = next(t for t in TYPES if isinstance(msg, convert.message_type(t)))
        text = msgdefs.complete_definition(type_)
        assert ("# " in text) == installed
        schema = Schema(id=1, name=msgdefs.schema_name(type_), encoding="ros2msg",
                        data=text.encode())
        decode = DecoderFactory().decoder_for("cdr", schema)
        assert decode is not None
        decoded = decode(serialize_message(msg))
        if isinstance(msg.data, str | int):
            assert decoded.data == msg.data
        else:  # pixels, compressed bytes, samples
            assert list(decoded.data) == list(msg.data)
        if hasattr(msg, "header"):
            assert (decoded.header.stamp.sec, decoded.header.frame_id) == \
                (msg.header.stamp.sec, msg.header.frame_id)


def test_outputs_written_without_ros_are_the_messages_the_node_publishes() -> None:
    pixels = np.random.default_rng(1).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    stamp = cdr.Stamp(12, 345, "front_camera")
    for type_, value in [("std_msgs/Int32", 7), ("std_msgs/Int32", np.int64(-3)),
                         ("std_msgs/String", "4 people"),
                         ("sensor_msgs/Image", Frame.from_pixels(pixels)),
                         ("sensor_msgs/Image", Frame(encode_image(pixels, "png"), "png"))]:
        written = serialize(type_, value, stamp)
        published = convert.to_message(type_, value, stamp)
        assert deserialize_message(written, convert.message_type(type_)) == published, type_


def test_the_recording_modules_do_not_import_ros() -> None:
    modules = ["topics.definitions", "topics.codec", "topics.types", "recording.recorder",
               "recording.mcap_reader", "recording.replay"]
    imports = "; ".join(f"import oricf.gateway.{name}" for name in modules)
    check = ("import sys; bad = sorted(m for m in sys.modules if m.split('.')[0] in "
             "('rclpy', 'sensor_msgs', 'std_msgs', 'builtin_interfaces')); assert not bad, bad")
    result = subprocess.run([sys.executable, "-c", f"{imports}; {check}"],
                            capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
