"""sensor_msgs/Image and CompressedImage read straight from their serialized (CDR) bytes;
any message of definitions.DEFINITIONS written from its fields (`write`: what recordings
made without ROS hold).

Camera routes take frames serialized (rclpy's `raw=True`): rclpy would otherwise build a
Python message first, copying the pixels into an array.array. Reading the few fields here
and slicing the pixels out once is cheaper. No ROS import.

Layout (the ROS 2 IDL mapped to plain CDR): a 4-byte encapsulation header whose second byte
says the byte order, then every field aligned to its own size, counted from the end of that
header. Strings are a uint32 length including a final NUL, then the bytes; sequences of
uint8 are a uint32 count, then the bytes. The images read have no 8-byte fields, so the CDR
and plain CDR2 encodings lay them out alike. Writing produces little-endian XCDR1 (8-byte
fields aligned to 8), as rclpy does on x86-64 and ARM.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.topics import definitions
from oricf.gateway.topics.definitions import Field

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

    def put(self, data: bytes, align: int = 1) -> None:
        padding = -self._size % align
        if padding:
            self._parts.append(b"\0" * padding)
        self._parts.append(data)  # the caller's bytes, joined once by getvalue()
        self._size += padding + len(data)

    def primitive(self, type_: str, value: Any) -> None:
        code = PRIMITIVES[type_]
        try:
            self.put(struct.pack("<" + code, value), struct.calcsize(code))
        except struct.error:
            article = "an" if type_[0] in "aeiou" else "a"
            raise ValueError(f"{value} does not fit {article} {type_}") from None

    def string(self, text: str) -> None:
        data = text.encode() + b"\0"
        self.primitive("uint32", len(data))
        self.put(data)

    def getvalue(self) -> bytes:
        return b"".join(self._parts)


# struct codes of the primitive types (string is written apart)
PRIMITIVES = {"bool": "?", "byte": "B", "char": "B", "int8": "b", "uint8": "B", "int16": "h",
              "uint16": "H", "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q",
              "float32": "f", "float64": "d"}
# sequences of these may be given as bytes or a numpy array: written in one piece
BULK = {"uint8": "u1", "byte": "u1", "char": "u1", "int8": "i1", "int16": "<i2"}


def write(type_: str, fields: Mapping[str, Any]) -> bytes:
    """A message of a type of definitions.DEFINITIONS, serialized from its fields by name
    (nested messages as mappings too); a field left out takes its definition's default,
    or zero, empty. Raises ValueError for a number that does not fit its field."""
    writer = _Writer()
    _message(writer, type_, fields)
    return writer.getvalue()


def header(stamp: Stamp) -> dict[str, Any]:
    """A std_msgs/Header's fields."""
    return {"stamp": {"sec": stamp.sec, "nanosec": stamp.nanosec}, "frame_id": stamp.frame_id}


def _message(writer: _Writer, type_: str, fields: Mapping[str, Any]) -> None:
    for field in definitions.layout(type_):
        value = fields.get(field.name)
        if field.count is None:
            _single(writer, field, value)
        elif field.count < 0:
            _sequence(writer, field, () if value is None else value)
        else:
            for item in [None] * field.count if value is None else value:
                _single(writer, field, item)


def _single(writer: _Writer, field: Field, value: Any) -> None:
    if field.type == "string":
        writer.string("" if value is None else value)
    elif field.type in PRIMITIVES:
        writer.primitive(field.type, (field.default or 0) if value is None else value)
    else:
        _message(writer, field.type, {} if value is None else value)


def _sequence(writer: _Writer, field: Field, value: Any) -> None:
    if field.type in BULK and not isinstance(value, (list, tuple)):
        # bytes pass as they are (a camera frame's pixels are not copied here)
        data = value if isinstance(value, bytes) else np.asarray(value, BULK[field.type])
        data = data if isinstance(data, bytes) else data.tobytes()
        size = int(BULK[field.type][-1])
        writer.primitive("uint32", len(data) // size)
        writer.put(data, size)
        return
    writer.primitive("uint32", len(value))
    for item in value:
        _single(writer, field, item)
