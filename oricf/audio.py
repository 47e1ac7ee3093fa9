"""Audio helpers shared by the speech service, the gateway and the demo.

Samples travel as little-endian signed 16-bit PCM (``pcm_s16le``) or as a WAV file; models
want mono float32 at 16 kHz. Everything here is numpy only (no audio library needed), and
every problem with the caller's bytes is an InvalidInput that says what is wrong.
"""

from __future__ import annotations

import math
import shutil
import struct
import subprocess
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from pydantic import Field

from oricf.config import Schema
from oricf.errors import InvalidInput

ENCODINGS = ("pcm_s16le", "wav")
MODEL_RATE = 16000
INT16_SCALE = 32768.0
MAX_RATE = 384_000
# Below telephone rate there is no speech to recognise, and a tiny rate turns a few bytes
# into hours of audio to resample and scan.
MIN_RATE = 8000
MAX_CHANNELS = 32

WAVE_FORMAT_PCM = 0x0001
WAVE_FORMAT_EXTENSIBLE = 0xFFFE
# A data chunk this large (or 0) is a placeholder written by a tool that could not seek back
# (0x7FFFF000 from espeak-ng, 0xFFFFFFFF from others): the data runs to the end of the file.
STREAMED_DATA_SIZE = 0x7FFF0000


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


def pcm_from_bytes(data: bytes, sample_rate: int, channels: int = 1) -> PcmAudio:
    """Reads interleaved pcm_s16le bytes; the byte count must hold whole frames."""
    check_format(sample_rate, channels)
    frame_bytes = 2 * channels
    if len(data) % frame_bytes:
        raise InvalidInput(
            f"pcm_s16le data of {len(data)} bytes is not a whole number of frames "
            f"({frame_bytes} bytes each for {channels} channel(s) of 16-bit samples)")
    samples = np.frombuffer(data, dtype="<i2").reshape(-1, channels)
    return PcmAudio(samples, sample_rate)


def _chunks(data: bytes) -> tuple[dict[bytes, bytes], bool]:
    """The chunks of a RIFF/WAVE file by id (first of each kind), and whether the data chunk
    had a placeholder size (a WAV written to a pipe, e.g. by `espeak-ng --stdout`)."""
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise InvalidInput("not a WAV file (no RIFF/WAVE header)")
    chunks: dict[bytes, bytes] = {}
    offset = 12
    while offset + 8 <= len(data):
        chunk_id, size = struct.unpack_from("<4sI", data, offset)
        if chunk_id == b"data" and (size == 0 or size >= STREAMED_DATA_SIZE):
            chunks.setdefault(chunk_id, data[offset + 8:])
            return chunks, True
        body = data[offset + 8: offset + 8 + size]
        if len(body) < size:
            raise InvalidInput(
                f"truncated WAV file: chunk {chunk_id.decode('latin-1')!r} declares {size} "
                f"bytes but only {len(body)} are present")
        chunks.setdefault(chunk_id, body)
        offset += 8 + size + (size & 1)  # chunks are padded to an even length
    return chunks, False


def parse_wav(data: bytes) -> PcmAudio:
    """Reads a complete 16-bit PCM WAV file; refuses truncated or non-PCM files."""
    chunks, streamed = _chunks(data)
    fmt, body = chunks.get(b"fmt "), chunks.get(b"data")
    if fmt is None or len(fmt) < 16:
        raise InvalidInput("WAV file has no valid 'fmt ' chunk")
    if body is None:
        raise InvalidInput("WAV file has no 'data' chunk (truncated?)")
    tag, channels, rate, _byte_rate, _align, bits = struct.unpack_from("<HHIIHH", fmt)
    if tag == WAVE_FORMAT_EXTENSIBLE and len(fmt) >= 26:
        # The first two bytes of the sub-format GUID carry the real format tag.
        tag = struct.unpack_from("<H", fmt, 24)[0]
    if tag != WAVE_FORMAT_PCM or bits != 16:
        raise InvalidInput(
            f"unsupported WAV format (tag {tag:#06x}, {bits} bits): only 16-bit PCM is accepted")
    if streamed and channels:  # no declared length: a recording cut mid-frame is still audio
        body = body[:len(body) - len(body) % (2 * channels)]
    return pcm_from_bytes(body, rate, channels)


def decode_audio(data: bytes, encoding: str, sample_rate: int = 0, channels: int = 0,
                 max_seconds: float | None = None) -> PcmAudio:
    """Bytes as they travel (pcm_s16le or a WAV file) -> checked int16 frames.

    For pcm_s16le, sample_rate is required and channels 0 means 1; a WAV file carries both.
    """
    encoding = encoding.lower()
    if not encoding:
        raise InvalidInput(f"audio encoding is missing; use one of: {', '.join(ENCODINGS)}")
    if encoding not in ENCODINGS:
        raise InvalidInput(
            f"unknown audio encoding '{encoding}'; use one of: {', '.join(ENCODINGS)}")
    if not data:
        raise InvalidInput("audio data is empty")
    if encoding == "wav":
        audio = parse_wav(data)
    else:
        audio = pcm_from_bytes(data, sample_rate, channels or 1)
    if audio.frames == 0:
        raise InvalidInput("the audio holds no samples")
    if max_seconds is not None and audio.duration_s > max_seconds:
        raise InvalidInput(f"audio of {audio.duration_s:.1f} s is over the limit of "
                           f"{max_seconds:g} s")
    return audio


def encode_wav(samples: np.ndarray, sample_rate: int) -> bytes:
    """A 16-bit PCM WAV file from int16 samples shaped (frames,) or (frames, channels)."""
    frames = (samples[:, None] if samples.ndim == 1 else samples).astype("<i2")
    channels = frames.shape[1]
    body = frames.tobytes()
    fmt = struct.pack("<HHIIHH", WAVE_FORMAT_PCM, channels, sample_rate,
                      sample_rate * 2 * channels, 2 * channels, 16)
    return (b"RIFF" + struct.pack("<I", 4 + 8 + len(fmt) + 8 + len(body)) + b"WAVE"
            + b"fmt " + struct.pack("<I", len(fmt)) + fmt
            + b"data" + struct.pack("<I", len(body)) + body)


def to_float32(samples: np.ndarray) -> np.ndarray:
    """int16 -> float32 in [-1, 1)."""
    return samples.astype(np.float32) / INT16_SCALE


def to_int16(samples: np.ndarray) -> np.ndarray:
    """float32 in [-1, 1] -> int16, clipped."""
    return np.clip(np.round(samples * INT16_SCALE), -INT16_SCALE, INT16_SCALE - 1).astype(np.int16)


def mix_down(frames: np.ndarray) -> np.ndarray:
    """(frames, channels) -> mono float32, the mean of the channels."""
    if frames.ndim == 1:
        return frames.astype(np.float32, copy=False)
    if frames.shape[1] == 1:
        return frames[:, 0].astype(np.float32, copy=False)
    return frames.astype(np.float32).mean(axis=1)


def to_model_input(audio: PcmAudio, rate: int = MODEL_RATE) -> np.ndarray:
    """Mono float32 at the model's rate: what a speech model takes."""
    mono = mix_down(to_float32(audio.samples))
    return resample(mono, audio.sample_rate, rate)


def resample(samples: np.ndarray, source_rate: int, target_rate: int) -> np.ndarray:
    """Band-limited resampling of mono float32 audio (see Resampler)."""
    if source_rate == target_rate:
        return samples.astype(np.float32, copy=False)
    resampler = Resampler(source_rate, target_rate)
    return np.concatenate([resampler.push(samples), resampler.flush()])


# Windowed-sinc interpolation: ZERO_CROSSINGS lobes each side of the low-pass kernel, and
# at most MAX_PHASES precomputed fractional offsets (an offset error below 1/2048 of a
# sample is inaudible and keeps the table small for awkward rate ratios like 44056 Hz).
ZERO_CROSSINGS = 12
MAX_PHASES = 1024
BLOCK = 8192   # outputs per tap matrix
ROLLOFF = 0.94  # cut-off as a share of the lower Nyquist rate: room for the transition band


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


def synthesize(text: str, voice: str = "en-us", rate: int = 160,
               sample_rate: int = MODEL_RATE) -> np.ndarray:
    """Real speech for tests, demos and benchmarks: espeak-ng, converted by sox.

    Returns mono int16 samples at sample_rate. `rate` is espeak-ng's words per minute.
    """
    for tool in ("espeak-ng", "sox"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool} is not installed (run scripts/setup.sh)")
    wav = subprocess.run(["espeak-ng", "-v", voice, "-s", str(rate), "--stdout", text],
                         check=True, capture_output=True).stdout
    raw = subprocess.run(
        ["sox", "-t", "wav", "-", "-t", "raw", "-r", str(sample_rate), "-c", "1", "-b", "16",
         "-e", "signed-integer", "-L", "-"],
        input=wav, check=True, capture_output=True).stdout
    return np.frombuffer(raw, dtype="<i2").copy()


class VadSettings(Schema):
    """How audio is cut into utterances by voice activity (Silero VAD, 32 ms windows at
    16 kHz): the ASR service's `endpointing:` and a gateway audio input's `vad:`."""

    threshold: float = Field(0.5, gt=0, lt=1, description="speech probability that starts speech")
    min_silence_ms: int = Field(
        400, ge=32, le=10_000, description="this much silence ends an utterance")
    speech_pad_ms: int = Field(
        200, ge=0, le=2_000, description="audio kept before and after the detected speech")
    min_speech_ms: int = Field(
        200, ge=0, le=10_000, description="shorter bursts (clicks, coughs) are dropped")
    max_utterance_s: float = Field(
        20.0, gt=1, le=60, description="an utterance this long is cut and transcribed (keep "
                                       "it under the ASR service's audio.max_audio_s)")
