"""Decodes the chunks of one TranscribeStream call into mono float32 at the model's rate.

The first chunk fixes the format (pcm_s16le, sample rate, channels); later chunks may leave
it unset but may not change it. Chunks may split a sample or a frame: the remainder waits
for the next chunk. Resampling is stateful, so chunk boundaries leave no trace.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from oricf.audio import Resampler, check_format, mix_down, pcm_from_bytes, to_float32
from oricf.errors import InvalidInput

STREAM_ENCODING = "pcm_s16le"


@dataclass(frozen=True)
class StreamFormat:
    sample_rate: int
    channels: int

    @property
    def frame_bytes(self) -> int:
        return 2 * self.channels


class StreamDecoder:
    def __init__(self, target_rate: int, max_seconds: float = float("inf")) -> None:
        self.target_rate = target_rate
        self.max_seconds = max_seconds
        self.seconds = 0.0  # of audio received so far
        self.format: StreamFormat | None = None
        self._carry = b""
        self._resampler: Resampler | None = None
        self._decode_ms = 0.0

    def push(self, data: bytes, encoding: str, sample_rate: int, channels: int) -> np.ndarray:
        """Samples of one chunk (possibly none while the chunk holds less than a frame)."""
        started = time.perf_counter()
        fmt = self._check_format(encoding.lower(), sample_rate, channels)
        data = self._carry + data
        whole = len(data) - len(data) % fmt.frame_bytes
        self._carry = data[whole:]
        frames = pcm_from_bytes(data[:whole], fmt.sample_rate, fmt.channels).samples
        self.seconds += len(frames) / fmt.sample_rate
        if self.seconds > self.max_seconds:
            raise InvalidInput(f"the stream carried more than {self.max_seconds:g} s of audio "
                               f"(audio.max_stream_s)")
        samples = self._convert(mix_down(to_float32(frames)), flush=False)
        self._decode_ms += (time.perf_counter() - started) * 1e3
        return samples

    def flush(self) -> np.ndarray:
        """What the resampler still holds at the end of the stream."""
        return self._convert(np.zeros(0, dtype=np.float32), flush=True)

    @property
    def stray_bytes(self) -> int:
        """Bytes of an incomplete frame left at the end (the caller's mistake)."""
        return len(self._carry)

    def take_decode_ms(self) -> float:
        """Decoding time since the last call."""
        spent, self._decode_ms = self._decode_ms, 0.0
        return spent

    def _convert(self, mono: np.ndarray, flush: bool) -> np.ndarray:
        if self._resampler is None:
            return mono
        out = self._resampler.push(mono)
        return np.concatenate([out, self._resampler.flush()]) if flush else out

    def _check_format(self, encoding: str, sample_rate: int, channels: int) -> StreamFormat:
        if self.format is None:
            if encoding != STREAM_ENCODING:
                raise InvalidInput(f"the first stream message must set audio.encoding to "
                                   f"'{STREAM_ENCODING}' (got '{encoding}')")
            check_format(sample_rate, channels or 1)
            self.format = StreamFormat(sample_rate, channels or 1)
            if sample_rate != self.target_rate:
                self._resampler = Resampler(sample_rate, self.target_rate)
            return self.format
        fmt = self.format
        if encoding not in ("", STREAM_ENCODING):
            raise InvalidInput(f"audio.encoding changed mid-stream to '{encoding}'")
        if sample_rate not in (0, fmt.sample_rate):
            raise InvalidInput(f"sample_rate changed mid-stream from {fmt.sample_rate} "
                               f"to {sample_rate} Hz")
        if channels not in (0, fmt.channels):
            raise InvalidInput(f"channels changed mid-stream from {fmt.channels} to {channels}")
        return fmt
