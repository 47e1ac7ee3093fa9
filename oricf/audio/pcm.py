"""Samples as they travel: little-endian signed 16-bit PCM (``pcm_s16le``), checked, and
converted to the mono float32 that models take."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oricf.errors import InvalidInput

MODEL_RATE = 16000
INT16_SCALE = 32768.0
MAX_RATE = 384_000
# Below telephone rate there is no speech to recognise, and a tiny rate turns a few bytes
# into hours of audio to resample and scan.
MIN_RATE = 8000
MAX_CHANNELS = 32


@dataclass(frozen=True)
class PcmAudio:
    """Interleaved int16 samples as a (frames, channels) array."""

    samples: np.ndarray
    sample_rate: int

    @property
    def channels(self) -> int:
        return int(self.samples.shape[1])

    @property
    def frames(self) -> int:
        return int(self.samples.shape[0])

    @property
    def duration_s(self) -> float:
        return self.frames / self.sample_rate


def check_format(sample_rate: int, channels: int) -> None:
    if sample_rate <= 0:
        raise InvalidInput("sample_rate must be > 0 Hz")
    if sample_rate < MIN_RATE:
        raise InvalidInput(f"sample_rate {sample_rate} Hz is below the {MIN_RATE} Hz minimum")
    if sample_rate > MAX_RATE:
        raise InvalidInput(f"sample_rate {sample_rate} Hz is above the {MAX_RATE} Hz limit")
    if not 1 <= channels <= MAX_CHANNELS:
        raise InvalidInput(f"channels must be 1 to {MAX_CHANNELS}, got {channels}")


def pcm_from_bytes(data: bytes | memoryview, sample_rate: int, channels: int = 1
                   ) -> PcmAudio:
    """Reads interleaved pcm_s16le bytes; the byte count must hold whole frames."""
    check_format(sample_rate, channels)
    frame_bytes = 2 * channels
    if len(data) % frame_bytes:
        raise InvalidInput(
            f"pcm_s16le data of {len(data)} bytes is not a whole number of frames "
            f"({frame_bytes} bytes each for {channels} channel(s) of 16-bit samples)")
    samples = np.frombuffer(data, dtype="<i2").reshape(-1, channels)
    return PcmAudio(samples, sample_rate)


def to_float32(samples: np.ndarray) -> np.ndarray:
    """int16 -> float32 in [-1, 1)."""
    out = samples.astype(np.float32)
    out /= INT16_SCALE  # in place: one array of the size of the input, not two
    return out


def to_int16(samples: np.ndarray) -> np.ndarray:
    """float32 in [-1, 1] -> int16, clipped."""
    return np.clip(np.round(samples * INT16_SCALE), -INT16_SCALE, INT16_SCALE - 1).astype(np.int16)


def mix_down(frames: np.ndarray) -> np.ndarray:
    """(frames, channels) -> mono float32, the mean of the channels."""
    if frames.ndim == 1:
        return frames.astype(np.float32, copy=False)
    if frames.shape[1] == 1:
        return frames[:, 0].astype(np.float32, copy=False)
    return frames.mean(axis=1, dtype=np.float32)
