"""What plays an `audio:` output (oricf.gateway.sinks.speaker declares it): speech played on
an audio output device through PortAudio (the `sounddevice` package) like the audio inputs:
'default', an index, a PortAudio name, or a PulseAudio sink's name (`pactl list short
sinks`), opened as PortAudio's 'pulse' device with PULSE_SINK naming it.

The route hands audio over (play) and goes on; a thread of the speaker's own plays it in
order. Pieces that follow each other within IDLE_S play in one stream, so the sentences of
an answer sound as one; the stream is closed when none follows. interrupt() (a barge-in)
drops what is queued and aborts the stream, which discards what the device still buffers
(LATENCY_S); the player looks for it every POLL_S. A device that stops taking samples, or
a PulseAudio sink that is gone, ends the answer (logged); the next one opens it again.

While a stream plays, the pipeline's Speaking says so (muted microphones hear silence).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from oricf.errors import ConfigError
from oricf.gateway.components import ComponentContext, Sink
from oricf.gateway.sinks.speaker_device import SampleBuffer, find_output, playback_rate
from oricf.gateway.sources import audio_device
from oricf.gateway.speaking import Speaking
from oricf.gateway.values import AudioClip, Record, SpokenAudio

log = logging.getLogger(__name__)

# The device's buffer: room for a callback that comes late on a busy machine (0.1 s broke
# up under load); a barge-in discards it, and the first sample does not wait for it.
LATENCY_S = 0.5
# Silence at the start of each stream: PortAudio's ALSA plugin into PulseAudio lost the
# first ~0.12 s of a new stream ("There are 12" heard as "Well 12").
LEAD_IN_S = 0.15
POLL_S = 0.02         # how often the player looks for a barge-in and the buffer's end
IDLE_S = 0.5          # a piece arriving within this after the last keeps the stream open
STALL_S = 2.0         # samples waiting this long untaken: the device stopped playing


@dataclass
class SpeakerStats:
    played: int = 0         # pieces played to the end
    dropped: int = 0        # asked for before a barge-in, or queued when it came
    cut: int = 0            # streams cut by a barge-in
    # When streams began to sound (the first sample at the device) and were cut, by the
    # clock (time.monotonic), the latest 100 of each.
    starts: deque[float] = field(default_factory=lambda: deque(maxlen=100))
    cuts: deque[float] = field(default_factory=lambda: deque(maxlen=100))


class Speaker:
    """Plays speech on one device (a speaker output's `device:`)."""

    def __init__(self, device: str, speaking: Speaking) -> None:
        self.device = find_output(device)
        self.rate = playback_rate(self.device, 22050)
        self.stats = SpeakerStats()
        self._speaking = speaking
        self._queue: deque[AudioClip] = deque()
        self._cond = threading.Condition()
        self._cut = False
        self._busy = False
        self._stopping = False
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name=f"speaker-{device}")
        speaking.on_interrupt(self.interrupt)
        self._thread.start()
        log.info("speaker: %s at %d Hz", self.device.describe(), self.rate)

    def play(self, audio: Any) -> None:
        if not isinstance(audio, AudioClip):
            raise TypeError(f"audio: {type(audio).__name__} is not audio")
        with self._speaking.lock:
            if isinstance(audio, SpokenAudio) and not self._speaking.current(audio.asked_at):
                self.stats.dropped += 1
                return
            with self._cond:
                self._queue.append(audio)
                self._cond.notify_all()

    def interrupt(self) -> None:
        """Barge-in: drops what is queued and cuts what is playing."""
        with self._cond:
            self.stats.dropped += len(self._queue)
            self._queue.clear()
            self._cut = True
            self._cond.notify_all()

    def _next(self, timeout: float | None) -> AudioClip | None:
        """The next queued piece; None at stop, at a barge-in, or after timeout."""
        with self._cond:
            self._cond.wait_for(lambda: self._queue or self._stopping or self._cut, timeout)
            if self._stopping or self._cut or not self._queue:
                return None
            self._busy = True
            return self._queue.popleft()

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cut = False  # a barge-in with nothing playing is over
            audio = self._next(None)
            if audio is None:
                if self._stopping:
                    return
                continue
            try:
                self._play_burst(audio)
            except audio_device.DeviceLost as exc:  # the next answer opens it again
                with self._cond:
                    self.stats.dropped += len(self._queue)
                    self._queue.clear()
                log.warning("speaker: %s; the rest of this answer is dropped", exc)
            except Exception:  # the speaker goes on with the next answer
                log.exception("speaker: %s failed", self.device.describe())
                time.sleep(1.0)
            finally:
                self._busy = False

    def _play_burst(self, audio: AudioClip) -> None:
        """Plays `audio` and every piece that follows within IDLE_S, in one stream. The
        stream pulls from a buffer (PortAudio's callback), so a piece that comes late
        leaves silence, never a broken sample."""
        buffer = SampleBuffer()
        buffer.append(np.zeros(int(self.rate * LEAD_IN_S), np.int16))
        buffer.append(audio.mono(self.rate))
        stream = self._open(buffer)
        self._speaking.started()
        try:
            stream.start()  # with its buffer filled: it sounds from now on
            self.stats.starts.append(time.monotonic() + LEAD_IN_S)
            if self._feed(stream, buffer):
                self.stats.played += buffer.pieces - 1  # not the lead-in
                time.sleep(stream.latency)  # the device plays out what it holds
                stream.stop()
            else:
                buffer.clear()
                stream.abort()  # what the device holds is discarded too
                self.stats.cut += 1
                self.stats.cuts.append(time.monotonic())
        finally:
            stream.close(ignore_errors=True)
            audio_device.stream_closed()
            self._speaking.stopped()

    def _open(self, buffer: SampleBuffer) -> Any:
        sd = audio_device.portaudio()
        try:
            with audio_device.pulse_target("PULSE_SINK", self.device.pulse_sink):
                return sd.OutputStream(device=self.device.index, samplerate=self.rate,
                                       channels=1, dtype="int16", latency=LATENCY_S,
                                       callback=buffer.fill)
        except sd.PortAudioError as exc:
            raise audio_device.DeviceLost(f"cannot open {self.device.describe()}: {exc}"
                                          ) from None

    def _feed(self, stream: Any, buffer: SampleBuffer) -> bool:
        """Adds the pieces that come to the buffer until none came for IDLE_S after it ran
        dry (True), or a barge-in or stop (False); raises DeviceLost."""
        empty_since: float | None = None
        checked = time.monotonic()
        while True:
            piece = self._next(POLL_S)
            if not stream.active or buffer.stalled(STALL_S):
                raise audio_device.DeviceLost(f"{self.device.describe()} stopped playing")
            if time.monotonic() - checked > audio_device.PRESENCE_CHECK_S:
                checked = time.monotonic()
                self._check_presence()
            if self._cut or self._stopping:
                return False
            if piece is not None:
                buffer.append(piece.mono(self.rate))
                empty_since = None
            elif buffer.empty:
                empty_since = empty_since or time.monotonic()
                if time.monotonic() - empty_since > IDLE_S:
                    return True

    def _check_presence(self) -> None:
        """PulseAudio moves a stream whose sink went away to another sink instead of ending
        it: a named sink that is gone counts as lost, so speech never goes on quietly
        playing somewhere else."""
        if self.device.pulse_sink is None:
            return
        sinks = audio_device.pulse_sinks()
        if sinks is not None and self.device.pulse_sink not in sinks:
            raise audio_device.DeviceLost(f"{self.device.describe()} is gone")

    @property
    def playing(self) -> bool:
        """True from taking a piece off the queue until its stream is closed."""
        return self._busy

    def idle(self, timeout: float) -> bool:
        """Waits until nothing is queued or playing (for tests and benchmarks)."""
        deadline = time.monotonic() + timeout
        while self._queue or self._busy:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True

    def close(self) -> None:
        with self._cond:
            self._stopping = True
            self._queue.clear()
            self._cond.notify_all()
        self._thread.join(timeout=5)


class Speakers(Sink):
    """A Speaker per device that the pipeline's `audio:` outputs name, opened (checked) at
    once: a device that is not there is a ConfigError naming the file and the key."""

    def __init__(self, context: ComponentContext) -> None:
        self.speakers: dict[str, Speaker] = {}
        config = context.config
        for name, route in config.routes.items():
            for i, output in enumerate(route.outputs):
                if output.audio is None or output.audio.device in self.speakers:
                    continue
                try:
                    self.speakers[output.audio.device] = Speaker(output.audio.device,
                                                                 context.speaking)
                except ConfigError as exc:
                    self.close()
                    raise ConfigError(f"{config.origin}: routes.{name}.outputs[{i}].audio."
                                      f"device: {exc}") from None

    def send(self, output: Any, value: Any, record: Record) -> None:
        self.speakers[output.audio.device].play(value)

    def close(self) -> None:
        for speaker in self.speakers.values():
            speaker.close()
