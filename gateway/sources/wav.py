"""WAV files for audio inputs, read with the standard library's `wave` module.

The header is read when the gateway starts, so a file that is missing, not a WAV file, cut
inside its header, or not 16-bit PCM is a ConfigError before anything runs. A data chunk
shorter than its header says (a recording cut off) is read as far as it goes, with a
warning at the end.
"""

from __future__ import annotations

import logging
import wave
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from oricf.audio import STREAMED_DATA_SIZE, check_format
from oricf.errors import ConfigError, InvalidInput

log = logging.getLogger(__name__)


def is_wav_path(spec: str) -> bool:
    """An audio input names a WAV file (rather than a device) by its .wav ending."""
    return spec.lower().endswith(".wav")


class WavFile:
    """An open 16-bit PCM WAV file: its format, then blocks of (frames, channels) int16."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        try:
            self._wave = wave.open(str(self.path), "rb")  # noqa: SIM115 (kept open to read)
        except OSError as exc:
            raise ConfigError(f"{self.path}: cannot read ({exc.strerror or exc})") from None
        except EOFError:
            raise ConfigError(f"{self.path}: not a WAV file (it ends inside its header: "
                              f"empty or truncated)") from None
        except wave.Error as exc:
            raise ConfigError(f"{self.path}: not a WAV file that can be read ({exc}); "
                              f"16-bit PCM is read") from None
        self.sample_rate = self._wave.getframerate()
        self.channels = self._wave.getnchannels()
        self.declared_frames = self._wave.getnframes()
        self.frames_read = 0
        width = self._wave.getsampwidth()
        try:
            if width != 2:
                raise InvalidInput(f"{8 * width}-bit samples; only 16-bit PCM is read "
                                   f"(convert: sox IN.wav -b 16 OUT.wav)")
            check_format(self.sample_rate, self.channels)
        except InvalidInput as exc:
            self.close()
            raise ConfigError(f"{self.path}: {exc}") from None

    @property
    def duration_s(self) -> float:
        return self.declared_frames / self.sample_rate

    def blocks(self, seconds: float) -> Iterator[np.ndarray]:
        """Consecutive blocks of about `seconds` each, until the end of the data."""
        per_block = max(1, int(seconds * self.sample_rate))
        frame_bytes = 2 * self.channels
        while data := self._wave.readframes(per_block):
            whole = len(data) - len(data) % frame_bytes  # a cut-off file may end mid-frame
            if not whole:
                break
            block = np.frombuffer(data[:whole], dtype="<i2").reshape(-1, self.channels)
            self.frames_read += len(block)
            yield block
        if self.frames_read < self.declared_frames and not self._placeholder_size():
            log.warning("%s: %d of the %d frames its header declares (truncated?)",
                        self.path, self.frames_read, self.declared_frames)

    def _placeholder_size(self) -> bool:
        """A tool writing to a pipe cannot go back to fill in the data size (see
        oricf.audio.STREAMED_DATA_SIZE): then the data simply runs to the end."""
        return self.declared_frames * 2 * self.channels >= STREAMED_DATA_SIZE

    def close(self) -> None:
        self._wave.close()
