"""The values a route carries, independent of ROS: frames, audio clips, records.

A record is the dict of named fields one message turns into as it passes through a route:
the input field (`image`, `audio`, `text`, `value`, and a camera frame's `header`), the
fields of the method's typed result (oricf.gateway.methods: `detections`, `transcript`,
`answer`, ...), and what post steps write. Which fields a route has is known when the
pipeline loads, so steps and outputs that name a missing one are refused then. Outputs pick
one field each (`from:`). Checks on incoming data raise InvalidInput naming the problem.

A camera frame's record also carries FRAME_TIME: when the frame was taken, in seconds on
its source's clock (a recording's recorded time, a video file's position in the file, a
live camera's stamp or time of arrival), so that steps that measure time (track) see the
time the frames show, not the pace at which they happen to be processed.
"""

from __future__ import annotations

import string
from dataclasses import dataclass
from typing import Any

import numpy as np

from oricf.audio import check_format, mix_down, resample, to_float32, to_int16
from oricf.errors import InvalidInput
from oricf.imaging import ENCODED, RAW_CHANNELS, check_size, decode_image, encode_image
from oricf.logs import quoted
from oricf.v1 import common_pb2, speech_pb2

Record = dict[str, Any]
# Record key: when a camera frame was taken (seconds; only differences within a route count).
FRAME_TIME = "frame_time"


def template_fields(template: str) -> set[str]:
    """The record fields a `str.format` template names (`{count}`, `{detections[0]}` and
    `{image.width}` name count, detections, image); a malformed template is a ValueError."""
    names = set()
    for _, field, _, _ in string.Formatter().parse(template):
        if field is not None:
            names.add(field.split(".", 1)[0].split("[", 1)[0])
    return names


@dataclass(frozen=True)
class Frame:
    """An image: raw pixels (rgb8, bgr8, mono8; rows unpadded) or encoded (jpeg, png)."""

    data: bytes
    encoding: str
    width: int = 0
    height: int = 0

    def pixels(self) -> np.ndarray:
        """BGR uint8 array (decodes encoded frames)."""
        return decode_image(self.data, self.encoding, self.width, self.height)

    def to_proto(self, transport: str = "raw", jpeg_quality: int = 80) -> common_pb2.Image:
        """For a request: raw frames pass unchanged, or are JPEG-encoded for remote endpoints."""
        if transport == "jpeg" and self.encoding in RAW_CHANNELS:
            data = encode_image(self.pixels(), "jpeg", jpeg_quality)
            return common_pb2.Image(data=data, encoding="jpeg", width=self.width,
                                    height=self.height)
        return common_pb2.Image(data=self.data, encoding=self.encoding, width=self.width,
                                height=self.height)

    def as_raw(self) -> Frame:
        """This frame as raw pixels: itself, or decoded to bgr8 if encoded (jpeg, png)."""
        return self if self.encoding in RAW_CHANNELS else Frame.from_pixels(self.pixels())

    @classmethod
    def from_pixels(cls, pixels: np.ndarray) -> Frame:
        """From a BGR uint8 array."""
        height, width = pixels.shape[:2]
        return cls(np.ascontiguousarray(pixels).tobytes(), "bgr8", width, height)


def raw_frame(data: bytes, encoding: str, width: int, height: int, step: int) -> Frame:
    """A sensor_msgs/Image's fields -> Frame, refusing anything that cannot be a valid image."""
    if encoding not in RAW_CHANNELS:
        raise InvalidInput(f"unsupported image encoding {quoted(encoding)}; "
                           f"use one of: {', '.join(RAW_CHANNELS)}")
    check_size(width, height)
    row = width * RAW_CHANNELS[encoding]
    step = step or row
    if step < row:
        raise InvalidInput(f"{encoding} image {width} px wide needs step >= {row}, got {step}")
    if len(data) != step * height:
        raise InvalidInput(f"{encoding} image {width}x{height} with step {step} needs "
                           f"{step * height:,} bytes, got {len(data):,}")
    if step != row:  # drop the row padding: the wire format has none
        rows = np.frombuffer(data, np.uint8).reshape(height, step)[:, :row]
        return Frame(rows.tobytes(), encoding, width, height)
    return Frame(data, encoding, width, height)


def compressed_frame(data: bytes, format_: str) -> Frame:
    """A sensor_msgs/CompressedImage -> Frame; format as image_transport writes it
    ("jpeg", "png", or "bgr8; jpeg compressed bgr8")."""
    text = format_.lower()
    encoding = next((e for e in ENCODED if e in text), "jpeg" if "jpg" in text else "")
    if not encoding:
        raise InvalidInput(f"unsupported compressed image format {quoted(format_)}; "
                           f"use jpeg or png")
    if not len(data):
        raise InvalidInput("compressed image data is empty")
    return Frame(data, encoding)


@dataclass(frozen=True)
class AudioClip:
    """One utterance: interleaved little-endian int16 PCM."""

    pcm: bytes
    sample_rate: int
    channels: int

    @property
    def duration_s(self) -> float:
        return len(self.pcm) / (2 * self.channels * self.sample_rate)

    def mono(self, rate: int) -> np.ndarray:
        """The clip as mono int16 samples at `rate` (mixed down, resampled)."""
        frames = np.frombuffer(self.pcm, "<i2").reshape(-1, self.channels)
        if self.channels == 1 and self.sample_rate == rate:
            return frames[:, 0]
        floats = resample(mix_down(to_float32(frames)), self.sample_rate, rate)
        return to_int16(floats)

    def to_proto(self) -> speech_pb2.Audio:
        return speech_pb2.Audio(data=self.pcm, encoding="pcm_s16le",
                                sample_rate=self.sample_rate, channels=self.channels)


@dataclass(frozen=True)
class SpokenAudio(AudioClip):
    """Synthesized speech (oricf.gateway.methods.synthesize): the audio of `text`, and the
    clock time (time.monotonic) the synthesis was asked for; speech asked for before a
    barge-in is never played (oricf.gateway.speaking)."""

    text: str = ""
    asked_at: float = 0.0


def audio_clip(samples: Any, sample_rate: int, channels: int) -> AudioClip:
    """int16 samples (a sequence or array) -> AudioClip, refusing empty or ragged audio."""
    check_format(sample_rate, channels)
    array = np.asarray(samples, dtype="<i2")
    if array.size == 0:
        raise InvalidInput("audio message carries no samples")
    if array.size % channels:
        raise InvalidInput(f"{array.size} samples are not a whole number of frames of "
                           f"{channels} channels")
    return AudioClip(array.tobytes(), sample_rate, channels)
