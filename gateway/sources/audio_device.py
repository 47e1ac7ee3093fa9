"""Audio capture devices through PortAudio (the `sounddevice` package, `oricf[audio]`).

A device is named as PortAudio knows it: 'default', an index, or (part of) a name from
`python -m sounddevice`. PortAudio on Linux reaches PulseAudio and PipeWire only through
their ALSA plugin, as one device called 'pulse' that records from the server's default
source; so a PulseAudio source's own name (`pactl list short sources`, e.g.
`alsa_input.usb-...` or a null sink's `oricf_test.monitor`) is also accepted and opened
as that 'pulse' device with PULSE_SOURCE naming the source.

PortAudio's callback thread only queues blocks; the source's thread reads them. A stream
that fails (a USB microphone pulled out, the sound server gone) raises DeviceLost, and the
source reopens it with backoff.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from oricf.errors import ConfigError

log = logging.getLogger(__name__)

BLOCK_FRAMES_AT_16K = 512   # 32 ms, one VAD window
QUEUE_BLOCKS = 300          # about 10 s: the reader may fall this far behind before drops
PULSE_DEVICE = "pulse"      # the ALSA plugin's device that PortAudio lists
# PulseAudio moves a stream whose source goes away to another source instead of ending it;
# so a named source's presence is checked this often, and its loss is a DeviceLost.
PRESENCE_CHECK_S = 2.0
# PULSE_SOURCE is read from the environment when the plugin connects (at open), and the
# environment is shared by the whole process: opens that set it take turns.
_open_lock = threading.Lock()
# Streams open in this process; PortAudio's device list is re-read only when there are
# none (re-reading it closes every stream).
_open_streams = 0


class NoSuchDevice(ConfigError):
    """No input device by that name (the message lists the ones there are)."""


class DeviceLost(Exception):
    """A device could not be opened, or its stream stopped delivering."""


@dataclass(frozen=True)
class Device:
    index: int                  # PortAudio's device index
    name: str                   # as PortAudio (or PulseAudio) calls it
    pulse_source: str | None    # a PulseAudio source, reached through PortAudio's 'pulse'
    max_channels: int
    default_rate: int

    def describe(self) -> str:
        if self.pulse_source:
            return f"PulseAudio source '{self.pulse_source}' (through PortAudio '{PULSE_DEVICE}')"
        return f"'{self.name}' (PortAudio device {self.index})"


def portaudio() -> ModuleType:
    """The sounddevice module, or a ConfigError saying what to install."""
    try:
        import sounddevice
    except ImportError:
        raise ConfigError("audio devices need the sounddevice package: "
                          "pip install 'oricf[audio]'") from None
    except OSError as exc:  # sounddevice is there, the PortAudio library is not
        raise ConfigError(f"audio devices need PortAudio ({exc}): "
                          f"apt install libportaudio2") from None
    return sounddevice


def pulse_sources() -> list[str] | None:
    """The PulseAudio (or PipeWire) server's sources; None if there is no server to ask
    (or no pactl to ask it with)."""
    pactl = shutil.which("pactl")
    if pactl is None:
        return None
    try:
        listing = subprocess.run([pactl, "list", "short", "sources"], capture_output=True,
                                 text=True, timeout=5, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    return [line.split("\t")[1] for line in listing.splitlines() if "\t" in line]


def _device(info: dict[str, Any], pulse_source: str | None = None) -> Device:
    return Device(int(info["index"]), str(info["name"]), pulse_source,
                  int(info["max_input_channels"]), int(info["default_samplerate"]))


def find_device(spec: str) -> Device:
    """The input device `spec` names: 'default', an index, a PortAudio name, or a
    PulseAudio source."""
    sd = portaudio()
    wanted: int | str | None = None if spec == "default" else (
        int(spec) if spec.isdigit() else spec)
    try:
        return _device(sd.query_devices(wanted, "input"))
    except (ValueError, sd.PortAudioError):
        pass
    if wanted is not None and spec in (pulse_sources() or []):
        pulse = [d for d in sd.query_devices() if d["name"] == PULSE_DEVICE
                 and d["max_input_channels"] > 0]
        if pulse:
            return _device(pulse[0], spec)
    raise NoSuchDevice(f"no audio input device '{spec}'; {available_devices(sd)}")


def available_devices(sd: ModuleType) -> str:
    inputs = [f"{d['index']} '{d['name']}' ({d['max_input_channels']} ch, "
              f"{d['default_samplerate']:g} Hz)"
              for d in sd.query_devices() if d["max_input_channels"] > 0]
    text = f"PortAudio input devices: {', '.join(inputs) or 'none'}"
    sources = pulse_sources()
    if sources:
        text += f"; PulseAudio sources: {', '.join(sources)}"
    return text + " (give 'default', an index or a name)"


def refresh_devices() -> None:
    """Makes PortAudio list the devices again (one plugged in since), if no stream is open."""
    sd = portaudio()
    with _open_lock:
        if _open_streams == 0:
            sd._terminate()
            sd._initialize()


def capture_rate(device: Device, sample_rate: int, channels: int) -> int:
    """`sample_rate` if the device captures at it, else the device's own rate (the source
    resamples); a channel count the device lacks is a ConfigError."""
    sd = portaudio()
    if channels > device.max_channels:
        raise ConfigError(f"{device.describe()} has {device.max_channels} input channel(s), "
                          f"not {channels}")
    for rate in dict.fromkeys((sample_rate, device.default_rate)):
        try:
            sd.check_input_settings(device.index, channels=channels, dtype="int16",
                                    samplerate=rate)
            return rate
        except sd.PortAudioError:
            continue
    raise ConfigError(f"{device.describe()} cannot capture {channels} channel(s) of 16-bit "
                      f"audio at {sample_rate} Hz or at its own {device.default_rate} Hz")


@contextlib.contextmanager
def pulse_target(variable: str, name: str | None) -> Iterator[None]:
    """Sets PULSE_SOURCE or PULSE_SINK (when `name` is given) around opening a stream: the
    ALSA plugin reads it when it connects, and the environment is the whole process's, so
    opens take turns. Counts the stream opened inside as open (refresh_devices)."""
    global _open_streams
    with _open_lock:
        saved = os.environ.get(variable)
        if name:
            os.environ[variable] = name
        try:
            yield
            _open_streams += 1
        finally:
            _restore(variable, saved)


def stream_closed() -> None:
    global _open_streams
    with _open_lock:
        _open_streams -= 1


def pulse_sinks() -> list[str] | None:
    """The PulseAudio (or PipeWire) server's sinks; None if there is no server to ask."""
    pactl = shutil.which("pactl")
    if pactl is None:
        return None
    try:
        listing = subprocess.run([pactl, "list", "short", "sinks"], capture_output=True,
                                 text=True, timeout=5, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    return [line.split("\t")[1] for line in listing.splitlines() if "\t" in line]


class Capture:
    """An open input stream of int16 blocks shaped (frames, channels)."""

    def __init__(self, device: Device, sample_rate: int, channels: int) -> None:
        global _open_streams
        sd = portaudio()
        self.device = device
        self.sample_rate = sample_rate
        self.channels = channels
        self.dropped = 0
        self._present_at = time.monotonic()
        self._blocks: queue.Queue[np.ndarray | None] = queue.Queue(maxsize=QUEUE_BLOCKS)
        with _open_lock:
            saved = os.environ.get("PULSE_SOURCE")
            if device.pulse_source:
                os.environ["PULSE_SOURCE"] = device.pulse_source
            try:
                self._stream = sd.InputStream(
                    device=device.index, samplerate=sample_rate, channels=channels,
                    dtype="int16", blocksize=BLOCK_FRAMES_AT_16K * sample_rate // 16000,
                    callback=self._callback, finished_callback=self._finished)
            except sd.PortAudioError as exc:
                raise DeviceLost(f"cannot open {device.describe()}: {exc}") from None
            finally:
                _restore("PULSE_SOURCE", saved)
            _open_streams += 1
        try:
            self._stream.start()
        except sd.PortAudioError as exc:
            self.close()
            raise DeviceLost(f"cannot start {device.describe()}: {exc}") from None

    def _callback(self, block: np.ndarray, frames: int, _time: Any, _status: Any) -> None:
        try:
            self._blocks.put_nowait(block.copy())
        except queue.Full:  # the reader is stuck; newer audio matters more than older
            self.dropped += 1

    def _finished(self) -> None:
        with contextlib.suppress(queue.Full):  # then read() sees the stream is inactive
            self._blocks.put_nowait(None)

    def read(self, timeout: float) -> np.ndarray | None:
        """The next block, or None if none came within timeout (a silent sound server may
        send nothing); raises DeviceLost once the stream has stopped."""
        try:
            block = self._blocks.get(timeout=timeout)
        except queue.Empty:
            block = None
            if self._stream.active:
                self._check_presence()
                return None
        if block is None:
            raise DeviceLost(f"{self.device.describe()} stopped delivering audio")
        self._check_presence()
        return block

    def _check_presence(self) -> None:
        if self.device.pulse_source is None \
                or time.monotonic() - self._present_at < PRESENCE_CHECK_S:
            return
        sources = pulse_sources()
        if sources is not None and self.device.pulse_source not in sources:
            raise DeviceLost(f"{self.device.describe()} is gone")
        self._present_at = time.monotonic()

    def close(self) -> None:
        global _open_streams
        try:
            self._stream.close(ignore_errors=True)
        finally:
            with _open_lock:
                _open_streams -= 1


def _restore(name: str, value: str | None) -> None:
    if value is None:
        os.environ.pop(name, None)
    else:
        os.environ[name] = value
