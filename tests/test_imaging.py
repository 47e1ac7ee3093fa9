"""Image decoding refuses every malformed input with a message a person understands."""

import cv2
import numpy as np
import pytest

from oricf.errors import InvalidInput
from oricf.imaging import decode_image, encode_image
from tests.support.data import image


def test_jpeg_png_and_raw_decode_to_the_same_pixels() -> None:
    bgr = cv2.imread(str(image("person.jpg")))
    h, w = bgr.shape[:2]
    png = encode_image(bgr, "png")
    assert np.array_equal(decode_image(png, "png"), bgr)
    assert np.array_equal(decode_image(encode_image(bgr, "rgb8"), "rgb8", w, h), bgr)
    assert np.array_equal(decode_image(bgr.tobytes(), "bgr8", w, h), bgr)
    mono = decode_image(encode_image(bgr, "mono8"), "mono8", w, h)
    assert mono.shape == (h, w, 3)
    jpeg = decode_image(image("person.jpg").read_bytes(), "jpeg")
    assert jpeg.shape == bgr.shape


@pytest.mark.parametrize(
    ("data", "encoding", "width", "height", "message"),
    [
        (b"", "jpeg", 0, 0, "image data is empty"),
        (b"\xff\xd8\xff\xe0garbage", "jpeg", 0, 0, "not a valid JPEG"),
        (b"\x00" * 10, "rgb8", 2, 2, "needs 12 bytes"),
        (b"\x00" * 12, "rgb8", 0, 2, "width and height must be > 0"),
        (b"\x00" * 12, "yuv422", 2, 2, "unknown image encoding 'yuv422'"),
        (b"\x00" * 3, "bgr8", 100_000, 100_000, "over the limit"),
    ],
)
def test_bad_images_are_refused(data: bytes, encoding: str, width: int, height: int,
                                message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        decode_image(data, encoding, width, height)


def test_declared_size_must_match_an_encoded_image() -> None:
    with pytest.raises(InvalidInput, match="declared as 10x10"):
        decode_image(image("person.jpg").read_bytes(), "jpeg", 10, 10)


def test_png_bomb_is_refused_before_decoding() -> None:
    header = b"\x89PNG\r\n\x1a\n" + b"\x00\x00\x00\rIHDR" + (60000).to_bytes(4, "big") * 2
    with pytest.raises(InvalidInput, match="60000x60000 is over the limit"):
        decode_image(header + b"\x00" * 32, "png")
