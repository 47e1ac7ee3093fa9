"""What the audio of one request may cost to decode: its length (audio.max_audio_s) and its
size as 16-bit samples at its own rate and channel count (audio.max_decoded_mb).

The size is what bounds the work: a FLAC file of 20 KB can hold 30 s of 384 kHz audio in 8
channels, 90 million samples that must all be decoded, mixed down and resampled. A file whose
header says how long it is gets refused before any of it is decoded; every file is counted
again as its samples arrive, since a header may lie.
"""

from __future__ import annotations

from oricf.errors import InvalidInput
from oricf.services.asr.config import AudioSettings

SAMPLE_BYTES = 2  # 16-bit samples
MB = 1024 * 1024


class AudioLimits:
    def __init__(self, settings: AudioSettings) -> None:
        self.max_seconds = settings.max_audio_s
        self.max_decoded_mb = settings.max_decoded_mb

    def max_frames(self, rate: int, channels: int) -> int:
        """The most frames of audio at this rate and channel count within both limits."""
        by_size = int(self.max_decoded_mb * MB) // (SAMPLE_BYTES * channels)
        return min(int(self.max_seconds * rate), by_size)

    def check(self, frames: int, channels: int, rate: int, source: str = "audio") -> None:
        """Refuses audio of this many frames; `source` says whose count it is: "audio"
        decoded, or "the FLAC file's header" before decoding."""
        seconds = frames / rate
        if seconds > self.max_seconds:
            raise InvalidInput(f"{source}: {seconds:.1f} s, over the limit of "
                               f"{self.max_seconds:g} s (audio.max_audio_s)")
        mb = frames * channels * SAMPLE_BYTES / MB
        if mb > self.max_decoded_mb:
            raise InvalidInput(
                f"{source}: {seconds:.1f} s at {rate} Hz in {channels} channel(s), {mb:.1f} MB "
                f"of 16-bit samples, over the limit of {self.max_decoded_mb:g} MB "
                f"(audio.max_decoded_mb)")

    def check_decoding(self, frames: int, channels: int, rate: int) -> None:
        """Refuses audio as soon as more than the limits allow has been decoded (the file
        may hold far more; the rest is never decoded)."""
        if frames > self.max_frames(rate, channels):
            self.check(frames, channels, rate, "audio decoded so far")
