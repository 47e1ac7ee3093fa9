"""Hostile and unusual JPEGs made from real ones: repeated scans, EXIF orientation, lying
frame headers, large ones."""

from __future__ import annotations

import cv2
import numpy as np

EOI = b"\xff\xd9"


def progressive(image: np.ndarray) -> bytes:
    return bytes(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[1].tobytes())


def with_repeated_scans(jpeg: bytes, extra: int) -> bytes:
    """A progressive JPEG with its last scan (SOS segment and data) repeated `extra` more
    times: every copy is another pass of the decoder over the whole image."""
    assert jpeg.endswith(EOI)
    last = jpeg.rfind(b"\xff\xda")
    return jpeg[:-2] + jpeg[last:-2] * extra + EOI


def with_orientation(jpeg: bytes, orientation: int = 6) -> bytes:
    """The JPEG with an APP1 Exif segment saying Orientation=`orientation` (6: the camera was
    turned 90 degrees clockwise, as phones write), right after its start of image."""
    entry = ((0x0112).to_bytes(2, "big") + (3).to_bytes(2, "big")  # tag, type SHORT
             + (1).to_bytes(4, "big") + orientation.to_bytes(2, "big") + b"\x00\x00")
    tiff = b"MM\x00\x2a" + (8).to_bytes(4, "big") + (1).to_bytes(2, "big") + entry + bytes(4)
    body = b"Exif\x00\x00" + tiff
    return jpeg[:2] + b"\xff\xe1" + (len(body) + 2).to_bytes(2, "big") + body + jpeg[2:]


def blank(width: int, height: int) -> bytes:
    """A real black JPEG of width x height: a few hundred kilobytes at 6000x6000 that the
    decoder fills in whole (3 bytes a pixel)."""
    return bytes(cv2.imencode(".jpg", np.zeros((height, width, 3), np.uint8))[1].tobytes())


def claiming(width: int, height: int) -> bytes:
    """A real 8x8 JPEG of a few hundred bytes whose frame header claims width x height: the
    decoder allocates the claimed size and fills it in."""
    data = bytearray(cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))[1].tobytes())
    at = data.index(b"\xff\xc0")
    data[at + 5:at + 9] = height.to_bytes(2, "big") + width.to_bytes(2, "big")
    return bytes(data)


def slow_to_decode(side: int = 6000, scans: int = 64) -> bytes:
    """A legal progressive JPEG of side x side with `scans` scans: within every limit, but
    the decoder works for a while on it."""
    image = np.zeros((side, side, 3), np.uint8)
    cv2.circle(image, (side // 2, side // 2), side // 3, (40, 200, 90), -1)
    return with_repeated_scans(progressive(image), scans - 10)
