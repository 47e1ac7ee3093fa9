"""The camera routes' CDR reader, and the writer of recorded outputs, against rclpy's own
serializer."""

from __future__ import annotations

import struct

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Int32, String

from oricf.errors import InvalidInput
from oricf.gateway.topics import cdr


def image_message(frame_id: str, encoding: str, is_bigendian: int = 0) -> Image:
    msg = Image(height=3, width=2, encoding=encoding, is_bigendian=is_bigendian, step=8)
    msg.header.stamp.sec, msg.header.stamp.nanosec = -7, 123_456_789
    msg.header.frame_id = frame_id
    msg.data = bytes(range(24))
    return msg


# frame ids and encodings of every length modulo 4, so each field lands on each alignment
@pytest.mark.parametrize("frame_id", ["", "c", "ca", "cam", "camera_optical_frame"])
@pytest.mark.parametrize("encoding", ["rgb8", "bgr8", "mono8", "8UC3x"])
def test_images_read_as_rclpy_wrote_them(frame_id: str, encoding: str) -> None:
    msg = image_message(frame_id, encoding, is_bigendian=1)
    read = cdr.image(serialize_message(msg))
    assert read.header == cdr.Stamp(-7, 123_456_789, frame_id)
    assert (read.height, read.width, read.encoding, read.is_bigendian, read.step) == \
        (3, 2, encoding, 1, 8)
    assert read.data == bytes(range(24))


@pytest.mark.parametrize("frame_id", ["", "ab", "abc", "camera"])
@pytest.mark.parametrize("format_", ["jpeg", "png", "bgr8; jpeg compressed bgr8"])
def test_compressed_images_read_as_rclpy_wrote_them(frame_id: str, format_: str) -> None:
    msg = CompressedImage(format=format_)
    msg.header.frame_id = frame_id
    msg.header.stamp.sec = 1_700_000_000
    msg.data = b"\xff\xd8 jpeg bytes \xff\xd9"
    read = cdr.compressed_image(serialize_message(msg))
    assert read == cdr.CompressedImageFields(cdr.Stamp(1_700_000_000, 0, frame_id), format_,
                                             b"\xff\xd8 jpeg bytes \xff\xd9")


def test_big_endian_messages_are_read() -> None:
    def string(text: bytes) -> bytes:
        raw = text + b"\0"
        return struct.pack(">I", len(raw)) + raw + b"\0" * (-len(raw) % 4)

    buffer = (b"\x00\x00\x00\x00" + struct.pack(">iI", 5, 6) + string(b"cam") +
              string(b"jpeg") + struct.pack(">I", 3) + b"abc")
    assert cdr.compressed_image(buffer) == cdr.CompressedImageFields(
        cdr.Stamp(5, 6, "cam"), "jpeg", b"abc")


def test_every_truncation_is_refused_with_a_clear_error() -> None:
    whole = serialize_message(image_message("camera", "bgr8"))
    for size in range(len(whole)):
        with pytest.raises(InvalidInput, match="sensor_msgs/Image"):
            cdr.image(whole[:size])


def test_other_encapsulations_and_bad_strings_are_refused() -> None:
    whole = serialize_message(CompressedImage(format="jpeg"))
    with pytest.raises(InvalidInput, match="unsupported CDR encapsulation 0003"):
        cdr.compressed_image(b"\x00\x03" + whole[2:])  # parameter-list CDR
    not_utf8 = whole.replace(b"jpeg", b"\xff\xfepg")
    with pytest.raises(InvalidInput, match="not UTF-8"):
        cdr.compressed_image(not_utf8)
    no_nul = whole.replace(b"jpeg\0", b"jpegX")
    with pytest.raises(InvalidInput, match="final NUL"):
        cdr.compressed_image(no_nul)


@pytest.mark.parametrize("frame_id", ["", "c", "ca", "cam", "camera_optical_frame"])
@pytest.mark.parametrize("encoding", ["rgb8", "mono8", "8UC3x"])
def test_written_images_read_back_in_rclpy(frame_id: str, encoding: str) -> None:
    fields = cdr.ImageFields(cdr.Stamp(-7, 123_456_789, frame_id), 3, 2, encoding, 1, 8,
                             bytes(range(24)))
    written = cdr.write("sensor_msgs/Image", {
        "header": cdr.header(fields.header), "height": 3, "width": 2, "encoding": encoding,
        "is_bigendian": 1, "step": 8, "data": fields.data})
    assert cdr.image(written) == fields
    assert deserialize_message(written, Image) == image_message(frame_id, encoding, 1)


@pytest.mark.parametrize("text", ["", "a", "ab", "abc", "how many people?", "née 😀"])
def test_written_strings_and_numbers_read_back_in_rclpy(text: str) -> None:
    written = cdr.write("std_msgs/String", {"data": text})
    assert deserialize_message(written, String).data == text
    for number in (0, -1, 2**31 - 1, -(2**31)):
        written = cdr.write("std_msgs/Int32", {"data": number})
        assert deserialize_message(written, Int32).data == number
    with pytest.raises(ValueError, match="does not fit an int32"):
        cdr.write("std_msgs/Int32", {"data": 2**31})
