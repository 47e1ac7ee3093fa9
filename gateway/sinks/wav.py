"""Speech into WAV files (`wav: PATH`): every piece of audio appended, mono 16-bit at the
rate of the first (later pieces at another rate are resampled to it). The file is made new
when the first piece arrives, and its header is brought up to date after each piece, so the
file is a whole WAV file at any moment."""

from __future__ import annotations

import logging
import threading
import wave
from pathlib import Path
from typing import Any

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.components import ComponentContext, Sink, SinkKind
from oricf.gateway.values import AudioClip, Record

log = logging.getLogger(__name__)


class WavFiles(Sink):
    """Every wav output of a pipeline; one writer per path."""

    def __init__(self) -> None:
        self._files: dict[str, wave.Wave_write] = {}
        self._lock = threading.Lock()

    def write(self, path: str, audio: Any) -> None:
        if not isinstance(audio, AudioClip):
            raise TypeError(f"wav: {type(audio).__name__} is not audio")
        with self._lock:
            out = self._files.get(path)
            if out is None:
                out = self._open(Path(path).expanduser(), audio.sample_rate)
                self._files[path] = out
            out.writeframes(audio.mono(out.getframerate()).astype("<i2").tobytes())

    @staticmethod
    def _open(path: Path, rate: int) -> wave.Wave_write:
        path.parent.mkdir(parents=True, exist_ok=True)
        out = wave.open(str(path), "wb")  # noqa: SIM115 (closed in close())
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(rate)
        log.info("wav: writing speech to %s (%d Hz)", path, rate)
        return out

    def send(self, output: Any, value: Any, record: Record) -> None:
        self.write(output.wav, value)

    def close(self) -> None:
        with self._lock:
            for out in self._files.values():
                out.close()
            self._files.clear()


class WavOutput(Schema):
    wav: str | None = Field(
        None, description="speech into a WAV file, appended (the file is new at start)")


def open_files(context: ComponentContext) -> Sink:
    return WavFiles()


COMPONENT = SinkKind("wav", WavOutput, open_files, rank=6)
