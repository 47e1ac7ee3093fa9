"""An uploaded audio file (the OpenAI transcription API) -> mono float32 at the model's rate.

WAV goes through the service's own reader (oricf.audio.parse_wav); FLAC, OGG (Opus or
Vorbis) and MP3 are decoded by FFmpeg through PyAV, which faster-whisper already brings.
The format is told from the file's first bytes and FFmpeg is given only that demuxer, so a
file cannot make it read playlists or other files.

A small compressed file can expand into hours of samples, or into seconds of audio at
384 kHz in 8 channels, so what it may cost is bounded (limits.py): a FLAC file whose header
declares more is refused before decoding, and every file is decoded frame by frame, each
frame mixed down and resampled at once, and refused as soon as it passes the limits. What
decoding holds is the model's input and one frame, never the whole file at its own rate.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from typing import Any

import numpy as np

from oricf.audio import ModelInput, parse_wav
from oricf.errors import InvalidInput
from oricf.services.asr.limits import AudioLimits

SUPPORTED = "WAV, FLAC, OGG (Opus, Vorbis) or MP3"
# FFmpeg demuxer names of the compressed formats.
DEMUXERS = {"flac": "flac", "ogg": "ogg", "mp3": "mp3"}
# Formats whose header gives the exact length (FLAC's STREAMINFO): refused from it before
# decoding. Others' durations are FFmpeg's estimates, checked only as samples arrive.
EXACT_LENGTH = ("flac",)


@dataclass(frozen=True)
class Decoded:
    samples: np.ndarray  # mono float32 at the model's rate
    duration_s: float    # of the file's audio


def sniff(data: bytes) -> str:
    """The file's format from its magic bytes: wav, flac, ogg or mp3."""
    if data[:4] == b"RIFF" and data[8:12] == b"WAVE":
        return "wav"
    if data[:4] == b"fLaC":
        return "flac"
    if data[:4] == b"OggS":
        return "ogg"
    if data[:3] == b"ID3" or (len(data) > 1 and data[0] == 0xFF and data[1] & 0xE0 == 0xE0):
        return "mp3"
    raise InvalidInput(f"the file is not audio this service reads: send {SUPPORTED}")


def decode_upload(data: bytes, limits: AudioLimits, rate: int) -> Decoded:
    if not data:
        raise InvalidInput("the file is empty")
    kind = sniff(data)
    if kind == "wav":
        return _decode_wav(data, limits, rate)
    return _decode_compressed(data, kind, limits, rate)


def _decode_wav(data: bytes, limits: AudioLimits, rate: int) -> Decoded:
    pcm = parse_wav(data)  # a view of the upload's bytes: its size is the file's
    if pcm.frames == 0:
        raise InvalidInput("the WAV file holds no samples")
    limits.check(pcm.frames, pcm.channels, pcm.sample_rate)
    converter = ModelInput(pcm.sample_rate, pcm.channels, rate)
    converter.push(pcm.samples)
    return Decoded(converter.finish(), pcm.duration_s)


def _decode_compressed(data: bytes, kind: str, limits: AudioLimits, rate: int) -> Decoded:
    import av

    try:
        with av.open(io.BytesIO(data), format=DEMUXERS[kind]) as container:
            stream = next((s for s in container.streams if s.type == "audio"), None)
            if stream is None:
                raise InvalidInput(f"the {kind.upper()} file has no audio stream")
            return _frames(container, stream, kind, limits, rate)
    except InvalidInput:
        raise
    except Exception as exc:  # FFmpeg's errors, and whatever a broken file makes PyAV raise
        raise InvalidInput(f"cannot decode the {kind.upper()} file: "
                           f"{str(exc)[:200] or type(exc).__name__}") from None


def _declared_frames(stream: Any, rate: int) -> int:
    """The length the stream's header declares, in frames; 0 when it says none."""
    if stream.duration is None or stream.time_base is None:
        return 0
    return int(stream.duration * stream.time_base * rate)


def _frames(container: Any, stream: Any, kind: str, limits: AudioLimits,
            rate: int) -> Decoded:
    import av

    source_rate = int(stream.codec_context.sample_rate or 0)
    channels = int(stream.codec_context.channels or 0)
    converter = ModelInput(source_rate, channels, rate)  # checks the rate and channels
    if kind in EXACT_LENGTH:
        limits.check(_declared_frames(stream, source_rate), channels, source_rate,
                     f"the {kind.upper()} file's header")
    # Interleaved int16 at the file's own rate and channels, as a WAV file gives.
    resampler = av.AudioResampler(format="s16", layout=stream.layout, rate=source_rate)
    for frame in container.decode(stream):
        for out in resampler.resample(frame):
            samples = out.to_ndarray().reshape(-1, channels)
            limits.check_decoding(converter.frames + len(samples), channels, source_rate)
            converter.push(samples)
    if converter.frames == 0:
        raise InvalidInput(f"the {kind.upper()} file holds no samples")
    return Decoded(converter.finish(), converter.frames / source_rate)
