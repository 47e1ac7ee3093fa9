"""Image decoding, encoding and drawing shared by the detector service and the gateway.

Images travel as bytes plus `encoding`, `width` and `height` (the oricf.v1.Image message,
or a ROS sensor_msgs/Image). Decoding validates everything a caller can get wrong and
raises InvalidInput with a message a person understands; it never crashes on bad bytes.
Internally images are BGR uint8 arrays (OpenCV's order, and YOLOX's input order).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from oricf.errors import InvalidInput

RAW_CHANNELS = {"rgb8": 3, "bgr8": 3, "mono8": 1}
ENCODED = ("jpeg", "png")
ENCODINGS = (*ENCODED, *RAW_CHANNELS)
# Larger than any camera a robot carries (8K is 33 Mpx); refuses absurd sizes before allocating.
MAX_PIXELS = 40_000_000


@dataclass(frozen=True)
class Box:
    x_min: float
    y_min: float
    x_max: float
    y_max: float


@dataclass(frozen=True)
class Detection:
    label: str
    class_id: int
    score: float
    box: Box


def check_size(width: int, height: int, max_pixels: int = MAX_PIXELS) -> None:
    """Refuses zero, negative and absurd image sizes before anything is allocated."""
    if width <= 0 or height <= 0:
        raise InvalidInput(f"image size {width}x{height}: width and height must be > 0")
    if width * height > max_pixels:
        raise InvalidInput(
            f"image size {width}x{height} is over the limit of {max_pixels:,} pixels")


def decode_image(data: bytes, encoding: str, width: int = 0, height: int = 0,
                 max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """Bytes -> BGR uint8 array of shape (height, width, 3)."""
    encoding = encoding.lower()
    if encoding == "jpg":
        encoding = "jpeg"
    if encoding not in ENCODINGS:
        raise InvalidInput(
            f"unknown image encoding '{encoding}'; use one of: {', '.join(ENCODINGS)}")
    if not data:
        raise InvalidInput("image data is empty")
    if encoding in RAW_CHANNELS:
        return _decode_raw(data, encoding, width, height, max_pixels)
    return _decode_encoded(data, encoding, width, height, max_pixels)


def _decode_raw(data: bytes, encoding: str, width: int, height: int,
                max_pixels: int) -> np.ndarray:
    check_size(width, height, max_pixels)
    channels = RAW_CHANNELS[encoding]
    expected = width * height * channels
    if len(data) != expected:
        raise InvalidInput(
            f"{encoding} image {width}x{height} needs {expected:,} bytes "
            f"({width}x{height}x{channels}), got {len(data):,}")
    pixels = np.frombuffer(data, dtype=np.uint8).reshape(height, width, channels)
    if encoding == "rgb8":
        return cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR)
    if encoding == "mono8":
        return cv2.cvtColor(pixels, cv2.COLOR_GRAY2BGR)
    return pixels


def _decode_encoded(data: bytes, encoding: str, width: int, height: int,
                    max_pixels: int) -> np.ndarray:
    header = encoded_size(data, encoding)
    if header is not None:  # refuse decompression bombs before decoding
        check_size(header[0], header[1], max_pixels)
    image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise InvalidInput(f"image data is not a valid {encoding.upper()} file")
    actual_h, actual_w = image.shape[:2]
    if (width and width != actual_w) or (height and height != actual_h):
        raise InvalidInput(
            f"image declared as {width}x{height} but the {encoding.upper()} is "
            f"{actual_w}x{actual_h}")
    return image


def encoded_size(data: bytes, encoding: str) -> tuple[int, int] | None:
    """(width, height) from a PNG or JPEG header without decoding, if it can be read."""
    if encoding == "png" and len(data) >= 24 and data[:8] == b"\x89PNG\r\n\x1a\n":
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if encoding == "jpeg":
        i = 2
        while i + 9 < len(data) and data[i] == 0xFF:
            marker, length = data[i + 1], int.from_bytes(data[i + 2:i + 4], "big")
            if marker in (0xC0, 0xC1, 0xC2):  # start of frame: height then width
                return (int.from_bytes(data[i + 7:i + 9], "big"),
                        int.from_bytes(data[i + 5:i + 7], "big"))
            i += 2 + length
    return None


def encode_image(image: np.ndarray, encoding: str, jpeg_quality: int = 85) -> bytes:
    """BGR array -> bytes in the given encoding."""
    if encoding in ENCODED:
        ext = ".jpg" if encoding == "jpeg" else ".png"
        params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if encoding == "jpeg" else []
        ok, buffer = cv2.imencode(ext, image, params)
        if not ok:
            raise InvalidInput(f"could not encode the image as {encoding}")
        return buffer.tobytes()
    if encoding == "bgr8":
        return np.ascontiguousarray(image).tobytes()
    if encoding == "rgb8":
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB).tobytes()
    if encoding == "mono8":
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).tobytes()
    raise InvalidInput(f"unknown image encoding '{encoding}'; use one of: {', '.join(ENCODINGS)}")


def draw_detections(image: np.ndarray, detections: Iterable[Detection]) -> np.ndarray:
    """A copy of the image with a labelled box per detection."""
    canvas = image.copy()
    for det in detections:
        p1 = (round(det.box.x_min), round(det.box.y_min))
        p2 = (round(det.box.x_max), round(det.box.y_max))
        cv2.rectangle(canvas, p1, p2, (0, 200, 0), 2)
        caption = f"{det.label} {det.score:.2f}"
        cv2.putText(canvas, caption, (p1[0], max(p1[1] - 4, 12)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5, (0, 200, 0), 1, cv2.LINE_AA)
    return canvas
