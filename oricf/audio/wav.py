"""WAV files read and written without an audio library, and decode_audio: the bytes of a
request (pcm_s16le or a WAV file) as checked int16 frames."""

from __future__ import annotations

import struct

import numpy as np

from oricf.audio.pcm import PcmAudio, pcm_from_bytes
from oricf.errors import InvalidInput

ENCODINGS = ("pcm_s16le", "wav")
WAVE_FORMAT_PCM = 0x0001
WAVE_FORMAT_EXTENSIBLE = 0xFFFE
# A data chunk this large (or 0) is a placeholder written by a tool that could not seek back
# (0x7FFFF000 from espeak-ng, 0xFFFFFFFF from others): the data runs to the end of the file.
STREAMED_DATA_SIZE = 0x7FFF0000


def _chunks(data: bytes) -> tuple[dict[bytes, memoryview], bool]:
    """The chunks of a RIFF/WAVE file by id (first of each kind), and whether the data chunk
    had a placeholder size (a WAV written to a pipe, e.g. by `espeak-ng --stdout`). Each is a
    view of the file's bytes: a WAV file of many megabytes is not copied to be read."""
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise InvalidInput("not a WAV file (no RIFF/WAVE header)")
    view = memoryview(data)
    chunks: dict[bytes, memoryview] = {}
    offset = 12
    while offset + 8 <= len(data):
        chunk_id, size = struct.unpack_from("<4sI", data, offset)
        if chunk_id == b"data" and (size == 0 or size >= STREAMED_DATA_SIZE):
            chunks.setdefault(chunk_id, view[offset + 8:])
            return chunks, True
        body = view[offset + 8: offset + 8 + size]
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


def wav_header(sample_rate: int, channels: int, data_bytes: int) -> bytes:
    """The 44-byte header of a 16-bit PCM WAV file whose data chunk holds `data_bytes`
    (STREAMED_DATA_SIZE for a stream whose length is not known yet)."""
    fmt = struct.pack("<HHIIHH", WAVE_FORMAT_PCM, channels, sample_rate,
                      sample_rate * 2 * channels, 2 * channels, 16)
    return (b"RIFF" + struct.pack("<I", 4 + 8 + len(fmt) + 8 + data_bytes) + b"WAVE"
            + b"fmt " + struct.pack("<I", len(fmt)) + fmt
            + b"data" + struct.pack("<I", data_bytes))


def encode_wav(samples: np.ndarray, sample_rate: int) -> bytes:
    """A 16-bit PCM WAV file from int16 samples shaped (frames,) or (frames, channels)."""
    frames = (samples[:, None] if samples.ndim == 1 else samples).astype("<i2")
    body = frames.tobytes()
    return wav_header(sample_rate, frames.shape[1], len(body)) + body
