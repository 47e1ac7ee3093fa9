"""Band-limited resampling of mono float32 audio, one-shot or streaming, and the conversion
of any audio to what a speech model takes (mono float32 at 16 kHz), piece by piece."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from oricf.audio.pcm import MODEL_RATE, PcmAudio, check_format, mix_down, to_float32

# Windowed-sinc interpolation: ZERO_CROSSINGS lobes each side of the low-pass kernel, and
# at most MAX_PHASES precomputed fractional offsets (an offset error below 1/2048 of a
# sample is inaudible and keeps the table small for awkward rate ratios like 44056 Hz).
ZERO_CROSSINGS = 12
MAX_PHASES = 1024
BLOCK = 8192   # outputs per tap matrix
ROLLOFF = 0.94  # cut-off as a share of the lower Nyquist rate: room for the transition band
MIX_FRAMES = 65536  # frames converted to float and mixed down at once (ModelInput)


@lru_cache(maxsize=32)
def _filter_bank(phases: int, half: int, cutoff: float) -> np.ndarray:
    """Row p: kernel taps for an output p/phases of a sample past an input sample."""
    offsets = np.arange(-half + 1, half + 1, dtype=np.float64)      # k - floor(t)
    frac = np.arange(phases, dtype=np.float64)[:, None] / phases   # t - floor(t)
    x = offsets[None, :] - frac                                    # k - t
    window = 0.5 + 0.5 * np.cos(np.pi * np.clip(x / half, -1.0, 1.0))
    bank = cutoff * np.sinc(cutoff * x) * window
    return bank.astype(np.float32)


class Resampler:
    """Streaming band-limited resampler: push chunks of any length, then flush once.

    Output n sits at input time n * source / target; it is computed once the input reaches
    that far plus half a kernel, so chunked and one-shot resampling give the same samples.
    """

    def __init__(self, source_rate: int, target_rate: int) -> None:
        check_format(source_rate, 1)
        check_format(target_rate, 1)
        g = math.gcd(source_rate, target_rate)
        self.up, self.down = target_rate // g, source_rate // g
        cutoff = min(1.0, target_rate / source_rate) * ROLLOFF
        self.half = math.ceil(ZERO_CROSSINGS / cutoff)
        self.phases = min(self.up, MAX_PHASES)
        self.bank = _filter_bank(self.phases, self.half, cutoff)
        # Buffer holds input from absolute index self._start on; zeros stand before the start.
        self._buffer = np.zeros(self.half, dtype=np.float32)
        self._start = -self.half
        self._consumed = 0   # input samples pushed so far
        self._next = 0       # next output index

    def push(self, samples: np.ndarray) -> np.ndarray:
        self._buffer = np.concatenate([self._buffer, samples.astype(np.float32, copy=False)])
        self._consumed += len(samples)
        # Output n is ready once input floor(n * down / up) + half has arrived.
        ready_inputs = max(self._consumed - self.half, 0)
        return self._produce(-(-ready_inputs * self.up // self.down))

    def flush(self) -> np.ndarray:
        """The remaining output: the stream's end is padded with silence."""
        self._buffer = np.concatenate([self._buffer, np.zeros(self.half, dtype=np.float32)])
        return self._produce(-(-self._consumed * self.up // self.down))

    def _produce(self, total: int) -> np.ndarray:
        """Outputs self._next .. total-1, in blocks to bound the memory of the tap matrix."""
        blocks = [self._produce_block(n) for n in
                  np.array_split(np.arange(self._next, total, dtype=np.int64),
                                 max(1, -(-(total - self._next) // BLOCK)))]
        self._next = max(self._next, total)
        out = np.concatenate(blocks) if blocks else np.zeros(0, dtype=np.float32)
        # Keep only the input the next output's kernel can still reach.
        keep_from = self._next * self.down // self.up - self.half + 1 - self._start
        if keep_from > 0:
            self._buffer = self._buffer[keep_from:]
            self._start += keep_from
        return out

    def _produce_block(self, n: np.ndarray) -> np.ndarray:
        base = n * self.down // self.up
        phase = (n * self.down % self.up) * self.phases // self.up
        taps = base[:, None] + np.arange(-self.half + 1, self.half + 1)[None, :] - self._start
        return np.einsum("ij,ij->i", self._buffer[taps], self.bank[phase]).astype(np.float32)


class ModelInput:
    """Interleaved int16 frames of any rate and channel count, pushed in pieces of any
    length, as mono float32 at a model's rate.

    Each piece is converted, mixed down and resampled MIX_FRAMES frames at a time, so the
    memory this takes is the mono result plus one block, whatever the rate and channels of
    the input: converting 30 s of 384 kHz audio in 8 channels at once would hold 370 MB of
    float32 for a 2 MB result. The result is the same as one-shot conversion (Resampler).
    """

    def __init__(self, source_rate: int, channels: int, target_rate: int = MODEL_RATE) -> None:
        check_format(source_rate, channels)
        self.channels = channels
        self.frames = 0  # pushed so far, at the source rate
        self._resampler = (Resampler(source_rate, target_rate)
                           if source_rate != target_rate else None)
        self._parts: list[np.ndarray] = []

    def push(self, frames: np.ndarray) -> None:
        """Frames shaped (n, channels), or (n,) for mono."""
        for start in range(0, len(frames), MIX_FRAMES):
            mono = mix_down(to_float32(frames[start:start + MIX_FRAMES]))
            self._parts.append(mono if self._resampler is None else self._resampler.push(mono))
        self.frames += len(frames)

    def finish(self) -> np.ndarray:
        """All of it, the resampler's tail included; call once."""
        if self._resampler is not None:
            self._parts.append(self._resampler.flush())
        if not self._parts:
            return np.zeros(0, dtype=np.float32)
        return np.concatenate(self._parts)


def to_model_input(audio: PcmAudio, rate: int = MODEL_RATE) -> np.ndarray:
    """Mono float32 at the model's rate: what a speech model takes."""
    converter = ModelInput(audio.sample_rate, audio.channels, rate)
    converter.push(audio.samples)
    return converter.finish()


def resample(samples: np.ndarray, source_rate: int, target_rate: int) -> np.ndarray:
    """Band-limited resampling of mono float32 audio (see Resampler)."""
    if source_rate == target_rate:
        return samples.astype(np.float32, copy=False)
    resampler = Resampler(source_rate, target_rate)
    return np.concatenate([resampler.push(samples), resampler.flush()])
