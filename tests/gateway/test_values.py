"""Incoming images and audio: valid ones convert exactly, invalid ones say what is wrong."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from oricf.errors import InvalidInput
from oricf.gateway.values import Frame, audio_clip, compressed_frame, raw_frame
from oricf.imaging import decode_image, encode_image
from tests.support.data import video_frames


@pytest.fixture(scope="module")
def frame() -> np.ndarray:
    return video_frames([0])[0]


def test_row_padding_is_removed(frame: np.ndarray) -> None:
    height, width = frame.shape[:2]
    padded = np.zeros((height, width * 3 + 64), np.uint8)
    padded[:, :width * 3] = frame.reshape(height, -1)
    converted = raw_frame(padded.tobytes(), "bgr8", width, height, width * 3 + 64)
    assert np.array_equal(converted.pixels(), frame)


@pytest.mark.parametrize(("encoding", "width", "height", "step", "size", "message"), [
    ("yuv422", 4, 4, 8, 32, "unsupported image encoding 'yuv422'"),
    ("bgr8", 0, 0, 0, 0, "width and height must be > 0"),
    ("bgr8", 10, 10, 30, 299, "needs 300 bytes, got 299"),
    ("rgb8", 10, 10, 20, 200, "needs step >= 30, got 20"),
    ("mono8", 100_000, 100_000, 100_000, 0, "over the limit of 40,000,000 pixels"),
])
def test_invalid_raw_images_are_refused(encoding: str, width: int, height: int, step: int,
                                        size: int, message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        raw_frame(bytes(size), encoding, width, height, step)


def test_jpeg_transport_encodes_raw_frames_and_passes_encoded_ones(frame: np.ndarray) -> None:
    rgb = raw_frame(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB).tobytes(), "rgb8", 768, 576, 0)
    raw = rgb.to_proto("raw")
    assert (raw.encoding, len(raw.data)) == ("rgb8", 768 * 576 * 3)
    jpeg = rgb.to_proto("jpeg", 80)
    assert jpeg.encoding == "jpeg" and len(jpeg.data) < len(raw.data) / 8
    decoded = decode_image(jpeg.data, "jpeg")
    assert float(np.abs(decoded.astype(int) - frame.astype(int)).mean()) < 4  # same colours
    encoded = compressed_frame(encode_image(frame, "png"), "bgr8; png compressed bgr8")
    assert encoded.to_proto("jpeg").encoding == "png"  # already compressed: sent as is


@pytest.mark.parametrize(("fmt", "encoding"), [("jpeg", "jpeg"), ("jpg", "jpeg"), ("png", "png"),
                                               ("rgb8; jpeg compressed bgr8", "jpeg")])
def test_compressed_formats(fmt: str, encoding: str) -> None:
    assert compressed_frame(b"\xff\xd8", fmt).encoding == encoding


def test_bad_compressed_images_are_refused() -> None:
    with pytest.raises(InvalidInput, match="unsupported compressed image format 'tiff'"):
        compressed_frame(b"II*", "tiff")
    with pytest.raises(InvalidInput, match="compressed image data is empty"):
        compressed_frame(b"", "jpeg")


def test_annotated_frames_round_trip(frame: np.ndarray) -> None:
    assert np.array_equal(Frame.from_pixels(frame).pixels(), frame)


def test_audio_clips() -> None:
    stereo = audio_clip(np.arange(3200, dtype=np.int16), 16000, 2)
    assert stereo.duration_s == pytest.approx(0.1)
    wire = stereo.to_proto()
    assert (wire.encoding, wire.sample_rate, wire.channels) == ("pcm_s16le", 16000, 2)
    assert np.array_equal(np.frombuffer(wire.data, "<i2"), np.arange(3200))
    with pytest.raises(InvalidInput, match="carries no samples"):
        audio_clip([], 16000, 1)
    with pytest.raises(InvalidInput, match="3 samples are not a whole number of frames of 2"):
        audio_clip([1, 2, 3], 16000, 2)
    with pytest.raises(InvalidInput, match="sample_rate must be > 0"):
        audio_clip([1, 2], 0, 1)
