"""An uploaded audio file (the OpenAI transcription API) -> checked int16 frames.

WAV goes through the service's own reader (oricf.audio.decode_audio); FLAC, OGG (Opus or
Vorbis) and MP3 are decoded by FFmpeg through PyAV, which faster-whisper already brings.
The format is told from the file's first bytes and FFmpeg is given only that demuxer, so a
file cannot make it read playlists or other files. Decoding stops as soon as the audio is
longer than the service's limit: a small compressed file can expand into hours of samples.
"""

from __future__ import annotations

import io

import numpy as np

from oricf.audio import PcmAudio, check_format, decode_audio
from oricf.errors import InvalidInput

SUPPORTED = "WAV, FLAC, OGG (Opus, Vorbis) or MP3"
# FFmpeg demuxer names of the compressed formats.
DEMUXERS = {"flac": "flac", "ogg": "ogg", "mp3": "mp3"}


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


def decode_upload(data: bytes, max_seconds: float) -> PcmAudio:
    if not data:
        raise InvalidInput("the file is empty")
    kind = sniff(data)
    if kind == "wav":
        return decode_audio(data, "wav", max_seconds=max_seconds)
    return _decode_compressed(data, kind, max_seconds)


def _decode_compressed(data: bytes, kind: str, max_seconds: float) -> PcmAudio:
    import av

    try:
        with av.open(io.BytesIO(data), format=DEMUXERS[kind]) as container:
            stream = next((s for s in container.streams if s.type == "audio"), None)
            if stream is None:
                raise InvalidInput(f"the {kind.upper()} file has no audio stream")
            return _frames(container, stream, kind, max_seconds)
    except InvalidInput:
        raise
    except Exception as exc:  # FFmpeg's errors, and whatever a broken file makes PyAV raise
        raise InvalidInput(f"cannot decode the {kind.upper()} file: "
                           f"{str(exc)[:200] or type(exc).__name__}") from None


def _frames(container: object, stream: object, kind: str, max_seconds: float) -> PcmAudio:
    import av

    rate = int(stream.codec_context.sample_rate or 0)  # type: ignore[attr-defined]
    channels = int(stream.codec_context.channels or 0)  # type: ignore[attr-defined]
    check_format(rate, channels)
    # Interleaved int16 at the file's own rate and channels: the service resamples and
    # mixes down as for any other audio.
    resampler = av.AudioResampler(format="s16", layout=stream.layout, rate=rate)  # type: ignore[attr-defined]
    limit = int(max_seconds * rate)
    parts: list[np.ndarray] = []
    frames = 0
    for frame in container.decode(stream):  # type: ignore[attr-defined]
        for out in resampler.resample(frame):
            samples = out.to_ndarray().reshape(-1, channels)
            frames += len(samples)
            if frames > limit:
                raise InvalidInput(f"audio of more than {max_seconds:g} s is over the limit "
                                   f"of {max_seconds:g} s")
            parts.append(samples)
    if not parts:
        raise InvalidInput(f"the {kind.upper()} file holds no samples")
    return PcmAudio(np.concatenate(parts).astype(np.int16, copy=False), rate)
