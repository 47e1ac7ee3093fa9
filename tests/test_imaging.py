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
        (b"\xff\xd8\xff\xe0garbage", "jpeg", 0, 0, "corrupt or truncated"),
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


def _jpeg_claiming(width: int, height: int, marker: int = 0xC0, fill: int = 0) -> bytes:
    """A real small JPEG whose frame header is rewritten to claim width x height, with
    `fill` 0xFF fill bytes before the frame marker and the marker changed (SOF0, SOF2...)."""
    data = bytearray(cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))[1].tobytes())
    at = data.index(b"\xff\xc0")
    data[at + 1] = marker
    data[at + 5:at + 9] = height.to_bytes(2, "big") + width.to_bytes(2, "big")
    return bytes(data[:at] + b"\xff" * fill + data[at:])


@pytest.mark.parametrize(("marker", "fill"), [(0xC0, 0), (0xC0, 3), (0xC2, 1), (0xC1, 0),
                                              (0xC9, 2)])
def test_jpeg_bombs_are_refused_from_their_frame_header(marker: int, fill: int) -> None:
    """Fill bytes before a marker are legal; every SOFn carries the size."""
    with pytest.raises(InvalidInput, match="20000x20000 is over the limit"):
        decode_image(_jpeg_claiming(20000, 20000, marker, fill), "jpeg")


@pytest.mark.parametrize("marker", [0xC0, 0xC1, 0xC2])
def test_a_jpeg_whose_data_is_too_short_for_its_frame_is_refused(marker: int) -> None:
    """Within every size limit, but a few bytes for 640x480: the decoder would fill the rest
    in with grey and call it an image."""
    with pytest.raises(InvalidInput, match=r"JPEG scan 1 holds \d+ bytes, too few for the "
                                           r"640x480 image its frame header claims"):
        decode_image(_jpeg_claiming(640, 480, marker, 0), "jpeg")


@pytest.mark.parametrize("options", [[], [cv2.IMWRITE_JPEG_PROGRESSIVE, 1],
                                     [cv2.IMWRITE_JPEG_OPTIMIZE, 1],
                                     [cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                                      cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]])
def test_the_smallest_real_jpegs_still_decode(options: list[int]) -> None:
    """One colour: as few bits a block as an encoder writes, baseline or progressive."""
    for shape in [(1, 1, 3), (37, 91, 3), (1080, 1920, 3), (1080, 1920)]:
        data = cv2.imencode(".jpg", np.zeros(shape, np.uint8), options)[1].tobytes()
        assert decode_image(data, "jpeg").shape == (*shape[:2], 3)


def test_a_jpeg_with_fill_bytes_still_decodes() -> None:
    real = cv2.imencode(".jpg", np.full((8, 8, 3), 200, np.uint8))[1].tobytes()
    at = real.index(b"\xff\xc0")
    padded = real[:at] + b"\xff\xff" + real[at:]
    assert decode_image(padded, "jpeg").shape == (8, 8, 3)


def test_labels_that_lie_about_the_format_are_refused() -> None:
    png = encode_image(np.zeros((4, 4, 3), np.uint8), "png")
    jpeg = encode_image(np.zeros((4, 4, 3), np.uint8), "jpeg")
    with pytest.raises(InvalidInput, match="image labelled jpeg is a PNG file"):
        decode_image(png, "jpeg")
    with pytest.raises(InvalidInput, match="image labelled png is a JPEG file"):
        decode_image(jpeg, "png")
    bomb = b"\x89PNG\r\n\x1a\n" + b"\x00\x00\x00\rIHDR" + (60000).to_bytes(4, "big") * 2
    with pytest.raises(InvalidInput, match="labelled jpeg is a PNG"):
        decode_image(bomb + b"\x00" * 32, "jpeg")


@pytest.mark.parametrize(("data", "message"), [
    (b"GIF89a" + b"\x00" * 40, "neither a JPEG nor a PNG"),
    (b"\xff\xd8\xff\xda\x00\x08" + b"\x00" * 40, "no frame header before its image data"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF", "corrupt or truncated"),
    (b"\x89PNG\r\n\x1a\n\x00\x00", "without its IHDR"),
])
def test_headers_that_cannot_be_read_are_refused_before_decoding(data: bytes,
                                                                 message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        decode_image(data, "png" if data.startswith(b"\x89") else "jpeg")


def test_jpeg_scans_are_counted_in_the_marker_walk() -> None:
    """Scans inside an APP segment (an EXIF thumbnail) are skipped with the segment; 64
    scans decode, 65 are refused before decoding."""
    from tests.support.jpegs import progressive, with_repeated_scans

    real = progressive(np.full((16, 16, 3), 90, np.uint8))  # libjpeg's script: 10 scans
    thumbnail = b"Exif\x00\x00" + b"\xff\xda\x00\x08" * 100
    app1 = b"\xff\xe1" + (len(thumbnail) + 2).to_bytes(2, "big") + thumbnail
    assert decode_image(real[:2] + app1 + real[2:], "jpeg").shape == (16, 16, 3)
    assert decode_image(with_repeated_scans(real, 54), "jpeg").shape == (16, 16, 3)
    with pytest.raises(InvalidInput, match="more than 64 scans"):
        decode_image(with_repeated_scans(real, 55), "jpeg")
