"""Audio output devices through PortAudio, for the speaker (speaker_sink.py): finding one by
name (a PulseAudio sink too), the rate it plays, and the buffer its stream's callback plays
from."""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from oricf.errors import ConfigError
from oricf.gateway.sources import audio_device

PREFERRED_RATES = (48000, 44100, 22050, 16000)


@dataclass(frozen=True)
class OutputDevice:
    index: int
    name: str
    pulse_sink: str | None
    default_rate: int

    def describe(self) -> str:
        if self.pulse_sink:
            return f"PulseAudio sink '{self.pulse_sink}' (through PortAudio " \
                   f"'{audio_device.PULSE_DEVICE}')"
        return f"'{self.name}' (PortAudio device {self.index})"


def find_output(spec: str) -> OutputDevice:
    """The output device `spec` names, or a ConfigError listing those there are."""
    sd = audio_device.portaudio()
    wanted: int | str | None = None if spec == "default" else (
        int(spec) if spec.isdigit() else spec)
    try:
        info = sd.query_devices(wanted, "output")
        return OutputDevice(int(info["index"]), str(info["name"]), None,
                            int(info["default_samplerate"]))
    except (ValueError, sd.PortAudioError):
        pass
    if wanted is not None and spec in (audio_device.pulse_sinks() or []):
        for info in sd.query_devices():
            if info["name"] == audio_device.PULSE_DEVICE and info["max_output_channels"] > 0:
                return OutputDevice(int(info["index"]), str(info["name"]), spec,
                                    int(info["default_samplerate"]))
    outputs = [f"{d['index']} '{d['name']}'" for d in sd.query_devices()
               if d["max_output_channels"] > 0]
    text = f"no audio output device '{spec}'; PortAudio output devices: " \
           f"{', '.join(outputs) or 'none'}"
    sinks = audio_device.pulse_sinks()
    if sinks:
        text += f"; PulseAudio sinks: {', '.join(sinks)}"
    raise ConfigError(text + " (give 'default', an index or a name)")


def playback_rate(device: OutputDevice, rate: int) -> int:
    """`rate` if the device plays it, else the first it does of its own and common rates."""
    sd = audio_device.portaudio()
    for candidate in dict.fromkeys((rate, device.default_rate, *PREFERRED_RATES)):
        try:
            sd.check_output_settings(device.index, channels=1, dtype="int16",
                                     samplerate=candidate)
            return candidate
        except sd.PortAudioError:
            continue
    raise ConfigError(f"{device.describe()} plays no 16-bit mono audio")


class SampleBuffer:
    """Mono int16 pieces the stream's callback plays in order (silence when it runs dry)."""

    def __init__(self) -> None:
        self._pieces: deque[np.ndarray] = deque()
        self._offset = 0
        self._lock = threading.Lock()
        self._moved_at = time.monotonic()  # when the callback last took samples
        self.pieces = 0

    def append(self, samples: np.ndarray) -> None:
        with self._lock:
            if not self._pieces:
                self._moved_at = time.monotonic()
            self._pieces.append(samples)
            self.pieces += 1

    def stalled(self, seconds: float) -> bool:
        """Whether samples wait that the callback has not taken for `seconds`."""
        with self._lock:
            return bool(self._pieces) and time.monotonic() - self._moved_at > seconds

    def clear(self) -> None:
        with self._lock:
            self._pieces.clear()
            self._offset = 0

    @property
    def empty(self) -> bool:
        with self._lock:
            return not self._pieces

    def fill(self, out: np.ndarray, frames: int, _time: Any, _status: Any) -> None:
        """PortAudio's callback: the next `frames` samples into `out`."""
        filled = 0
        with self._lock:
            while filled < frames and self._pieces:
                piece = self._pieces[0]
                count = min(frames - filled, len(piece) - self._offset)
                out[filled:filled + count, 0] = piece[self._offset:self._offset + count]
                filled += count
                self._offset += count
                if self._offset == len(piece):
                    self._pieces.popleft()
                    self._offset = 0
            if filled:
                self._moved_at = time.monotonic()
        out[filled:] = 0
