"""sensor_msgs/Image and CompressedImage read straight from their serialized (CDR) bytes;
Image, String, Int32, Int16MultiArray and vision_msgs/Detection2DArray written (for
recordings made without ROS).

Camera routes take frames serialized (rclpy's `raw=True`): rclpy would otherwise build a
Python message first, copying the pixels into an array.array. Reading the few fields here
and slicing the pixels out once is cheaper. No ROS import.

Layout (the ROS 2 IDL mapped to plain CDR): a 4-byte encapsulation header whose second byte
says the byte order, then every field aligned to its own size, counted from the end of that
header. Strings are a uint32 length including a final NUL, then the bytes; sequences of
uint8 are a uint32 count, then the bytes. These messages have no 8-byte fields, so the CDR
and plain CDR2 encodings lay them out alike. Writing produces little-endian XCDR1, as rclpy
does on x86-64 and ARM.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from oricf.errors import InvalidInput

# Second byte of the encapsulation header: representation id (XCDR1 0/1, plain XCDR2 6/7);
# odd is little-endian.
PLAIN_ENCODINGS = frozenset({0, 1, 6, 7})
HEADER_SIZE = 4


@dataclass(frozen=True)
class Stamp:
    """std_msgs/Header: when and in which frame the image was taken."""

    sec: int
    nanosec: int
    frame_id: str


@dataclass(frozen=True)
class ImageFields:
    """sensor_msgs/Image (data is the pixel bytes as they were sent, row padding included)."""

    header: Stamp
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: bytes


@dataclass(frozen=True)
class CompressedImageFields:
    header: Stamp
    format: str
    data: bytes


class _Reader:
    def __init__(self, buffer: bytes, what: str) -> None:
        if len(buffer) < HEADER_SIZE:
            raise InvalidInput(f"serialized {what} of {len(buffer)} bytes has no CDR header")
        if buffer[0] != 0 or buffer[1] not in PLAIN_ENCODINGS:
            raise InvalidInput(f"serialized {what}: unsupported CDR encapsulation "
                               f"{buffer[:2].hex()}")
        self._buffer = buffer
        self._what = what
        self._pos = HEADER_SIZE
        order = "<" if buffer[1] & 1 else ">"
        self._u32 = struct.Struct(order + "I")
        self._i32 = struct.Struct(order + "i")

    def _take(self, size: int, align: int = 1) -> int:
        """Aligns, checks that size bytes are left, and returns where they start."""
        start = self._pos + (-(self._pos - HEADER_SIZE) % align)
        end = start + size
        if end > len(self._buffer):
            raise InvalidInput(f"serialized {self._what} is truncated: needs {end:,} bytes, "
                               f"has {len(self._buffer):,}")
        self._pos = end
        return start

    def uint32(self) -> int:
        return int(self._u32.unpack_from(self._buffer, self._take(4, 4))[0])

    def int32(self) -> int:
        return int(self._i32.unpack_from(self._buffer, self._take(4, 4))[0])

    def uint8(self) -> int:
        return self._buffer[self._take(1)]

    def octets(self) -> bytes:
        size = self.uint32()
        start = self._take(size)
        return self._buffer[start:start + size]

    def string(self) -> str:
        raw = self.octets()
        if not raw:  # some writers send an empty string as length 0
            return ""
        if raw[-1:] != b"\0":
            raise InvalidInput(f"serialized {self._what}: a string lacks its final NUL")
        try:
            return raw[:-1].decode()
        except UnicodeDecodeError as exc:
            raise InvalidInput(f"serialized {self._what}: a string is not UTF-8: {exc}") from None

    def header(self) -> Stamp:
        return Stamp(self.int32(), self.uint32(), self.string())


def image(buffer: bytes) -> ImageFields:
    """Serialized sensor_msgs/Image -> its fields (raises InvalidInput if malformed)."""
    read = _Reader(buffer, "sensor_msgs/Image")
    header = read.header()
    height, width, encoding = read.uint32(), read.uint32(), read.string()
    is_bigendian, step = read.uint8(), read.uint32()
    return ImageFields(header, height, width, encoding, is_bigendian, step, read.octets())


def compressed_image(buffer: bytes) -> CompressedImageFields:
    """Serialized sensor_msgs/CompressedImage -> its fields (raises InvalidInput)."""
    read = _Reader(buffer, "sensor_msgs/CompressedImage")
    header = read.header()
    return CompressedImageFields(header, read.string(), read.octets())


class _Writer:
    """Little-endian plain CDR, field by field; no padding after the last field (as rclpy)."""

    def __init__(self) -> None:
        self._parts = [b"\x00\x01\x00\x00"]  # representation XCDR1, little-endian
        self._size = 0  # bytes after the encapsulation header, for alignment

    def _put(self, data: bytes, align: int = 1) -> None:
        padding = -self._size % align
        if padding:
            self._parts.append(b"\0" * padding)
        self._parts.append(data)
        self._size += padding + len(data)

    def uint32(self, value: int) -> None:
        if not 0 <= value < 2**32:
            raise ValueError(f"{value} does not fit a uint32")
        self._put(struct.pack("<I", value), 4)

    def int32(self, value: int) -> None:
        if not -(2**31) <= value < 2**31:
            raise ValueError(f"{value} does not fit an int32")
        self._put(struct.pack("<i", value), 4)

    def uint8(self, value: int) -> None:
        self._put(bytes((value,)))

    def float64(self, value: float) -> None:
        self._put(struct.pack("<d", value), 8)

    def octets(self, data: bytes) -> None:
        self.uint32(len(data))
        self._put(data)

    def string(self, text: str) -> None:
        self.octets(text.encode() + b"\0")

    def header(self, stamp: Stamp) -> None:
        self.int32(stamp.sec)
        self.uint32(stamp.nanosec)
        self.string(stamp.frame_id)

    def getvalue(self) -> bytes:
        return b"".join(self._parts)


def write_int32(value: int) -> bytes:
    """std_msgs/Int32, serialized (raises ValueError out of range)."""
    write = _Writer()
    write.int32(value)
    return write.getvalue()


def write_string(text: str) -> bytes:
    """std_msgs/String, serialized."""
    write = _Writer()
    write.string(text)
    return write.getvalue()


def write_int16_array(samples: bytes) -> bytes:
    """std_msgs/Int16MultiArray with an empty layout, serialized; `samples` little-endian
    int16."""
    write = _Writer()
    write.uint32(0)  # layout.dim: no dimensions
    write.uint32(0)  # layout.data_offset
    write.uint32(len(samples) // 2)
    write._put(samples, 2)
    return write.getvalue()


@dataclass(frozen=True)
class BoxFields:
    """One vision_msgs/Detection2D: its id, one hypothesis, its box's centre and size."""

    id: str
    class_id: str
    score: float
    center_x: float
    center_y: float
    size_x: float
    size_y: float


def write_detection_array(header: Stamp, boxes: list[BoxFields]) -> bytes:
    """vision_msgs/Detection2DArray, serialized: each detection with the array's header,
    one hypothesis at an identity pose with zero covariance, and a box without rotation."""
    write = _Writer()
    write.header(header)
    write.uint32(len(boxes))
    for box in boxes:
        write.header(header)
        write.uint32(1)  # results
        write.string(box.class_id)
        write.float64(box.score)
        for value in (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, *[0.0] * 36):  # pose, covariance
            write.float64(value)
        for value in (box.center_x, box.center_y, 0.0, box.size_x, box.size_y):
            write.float64(value)
        write.string(box.id)
    return write.getvalue()


def write_image(image: ImageFields) -> bytes:
    """sensor_msgs/Image, serialized: the inverse of image()."""
    write = _Writer()
    write.header(image.header)
    write.uint32(image.height)
    write.uint32(image.width)
    write.string(image.encoding)
    write.uint8(image.is_bigendian)
    write.uint32(image.step)
    write.octets(image.data)
    return write.getvalue()
