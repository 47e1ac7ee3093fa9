"""What runs an audio input (oricf.gateway.sources.audio declares it): utterances cut from
an audio device's capture or a WAV file's blocks, handed to the route as AudioClips.

The audio is cut into utterances here, on the robot, by the ASR service's own voice-activity
endpointing (Silero VAD, oricf.audio.endpointing) rather than streamed whole to
TranscribeStream: a route item is then one utterance, so each Transcribe call has its
deadline, busy retries and fallback endpoint like every other call, only speech crosses the
network (not 32 kB/s of room noise), and no long-lived stream holds one of the service's
call slots. The cost is the VAD's ONNX file, which ships in the `asr` extra.

Any capture rate and channel count is mixed down to mono and resampled to 16 kHz (the VAD's
and Whisper's rate) before cutting. A device that does not exist is a ConfigError at start
naming the devices there are; one that fails while running is reopened with backoff, each
attempt logged. A WAV file plays at its own pace (a 10 s file takes 10 s, as a microphone
would), and its route ends at the file's end.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING

import numpy as np

from oricf.audio import MODEL_RATE, Resampler, VadSettings, mix_down, to_float32, to_int16
from oricf.errors import ConfigError, ModelMissing
from oricf.gateway.sources import audio_device
from oricf.gateway.sources.base import OnEnd, Submit
from oricf.gateway.sources.wav import WavFile, is_wav_path
from oricf.gateway.speaking import Speaking
from oricf.gateway.values import AudioClip, audio_clip
from oricf.tracing import span

if TYPE_CHECKING:
    from oricf.audio.endpointing import Utterance
    from oricf.audio.vad import SileroVad
    from oricf.gateway.config import InputConfig

log = logging.getLogger(__name__)

RECONNECT_MIN_S = 0.5
RECONNECT_MAX_S = 10.0
STEADY_S = 10.0       # a device that ran this long before failing starts its backoff afresh
READ_TIMEOUT_S = 0.25  # how often the capture loop looks at the stop flag
WAV_BLOCK_S = 0.1

_vad: SileroVad | None = None
_vad_lock = threading.Lock()


def shared_vad() -> SileroVad:
    """One Silero session for every audio route (sessions are thread-safe); loaded on the
    first audio route, so a gateway without one never loads onnxruntime's VAD session."""
    global _vad
    from oricf.audio.vad import SileroVad

    with _vad_lock:
        if _vad is None:
            vad = SileroVad()
            try:
                vad.load()
            except ModelMissing as exc:
                raise ConfigError(f"cutting audio into utterances needs the Silero VAD that "
                                  f"faster-whisper ships: pip install 'oricf[asr]' ({exc})"
                                  ) from None
            _vad = vad
        return _vad


class Utterances:
    """int16 blocks of any rate and channel count -> 16 kHz mono utterances (AudioClips)."""

    def __init__(self, vad: SileroVad, settings: VadSettings) -> None:
        from oricf.audio.endpointing import Endpointer, EndpointingSettings

        self._endpointer = Endpointer(vad.stream(), EndpointingSettings(**settings.model_dump()))
        self._resampler: Resampler | None = None

    def begin(self, sample_rate: int) -> None:
        """A new stretch of audio at this rate (a device opened or reopened)."""
        self._resampler = Resampler(sample_rate, MODEL_RATE) if sample_rate != MODEL_RATE \
            else None

    @property
    def voiced_s(self) -> float:
        """Seconds of speech in the utterance still open (0 when none is)."""
        return self._endpointer.voiced_s

    def push(self, frames: np.ndarray) -> list[AudioClip]:
        mono = mix_down(to_float32(frames))
        if self._resampler is not None:
            mono = self._resampler.push(mono)
        return self._clips(self._endpointer.push(mono))

    def end(self) -> list[AudioClip]:
        """The stretch ended (file end, device lost, stop): an open utterance is finished."""
        clips = []
        if self._resampler is not None:
            clips = self._clips(self._endpointer.push(self._resampler.flush()))
            self._resampler = None
        return clips + self._clips(self._endpointer.flush())

    @staticmethod
    def _clips(utterances: list[Utterance]) -> list[AudioClip]:
        return [audio_clip(to_int16(u.samples), MODEL_RATE, 1) for u in utterances]


class AudioSource:
    def __init__(self, route: str, config: InputConfig, submit: Submit, on_end: OnEnd,
                 speaking: Speaking | None = None) -> None:
        assert config.audio is not None
        self.route = route
        self.config = config
        self.spec = config.audio
        self.utterances = 0
        self.reconnects = 0
        self._submit = submit
        self._on_end = on_end
        self._stop = threading.Event()
        self._wav: WavFile | None = None
        self._speaking = speaking
        self._while_speaking = config.while_speaking or "mute"
        self._barge_in_s = (config.vad or VadSettings()).min_speech_ms / 1000
        self._barged_in = False
        key = f"routes.{route}.input.audio"
        try:  # everything that can be checked before the gateway runs, is
            self._cutter = Utterances(shared_vad(), config.vad or VadSettings())
            if is_wav_path(self.spec):
                self._wav = WavFile(self.spec)
            else:
                device = audio_device.find_device(self.spec)
                audio_device.capture_rate(device, config.sample_rate, config.channels)
        except ConfigError as exc:
            raise ConfigError(f"{key}: {exc}") from None
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"audio-{route}")

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    def _run(self) -> None:
        try:
            if self._wav is not None:
                self._play(self._wav)
            else:
                self._listen()
        except Exception:  # the source ends, the gateway and its other routes go on
            log.exception("route %s: audio input %s failed; the route ends", self.route,
                          self.spec)
        finally:
            try:
                self._send(self._cutter.end())
            finally:
                self._on_end(self.route)

    def _send(self, clips: list[AudioClip]) -> None:
        for clip in clips:
            self.utterances += 1
            log.debug("route %s: utterance %d, %.2f s", self.route, self.utterances,
                      clip.duration_s)
            # The root of a question's trace (docs/tracing.md): its route is the child.
            with span("utterance cut", attributes={
                    "oricf.route": self.route, "oricf.audio_s": clip.duration_s}):
                self._submit(lambda c=clip: {"audio": c})

    def _play(self, wav: WavFile) -> None:
        log.info("route %s: reading %s (%.1f s, %d Hz, %d channel(s))", self.route, wav.path,
                 wav.duration_s, wav.sample_rate, wav.channels)
        self._cutter.begin(wav.sample_rate)
        started = time.monotonic()
        try:
            for block in wav.blocks(WAV_BLOCK_S):
                if self._stop.is_set():
                    return
                self._hear(block)
                ahead = started + wav.frames_read / wav.sample_rate - time.monotonic()
                if ahead > 0:
                    self._stop.wait(ahead)
        finally:
            wav.close()
        self._send(self._cutter.end())
        log.info("route %s: %s ended after %d utterance(s); the route ends", self.route,
                 wav.path, self.utterances)

    def _listen(self) -> None:
        """Captures until stopped; a device that fails or vanishes is reopened with backoff."""
        backoff = RECONNECT_MIN_S
        while not self._stop.is_set():
            try:
                capture = self._open()
            except (audio_device.DeviceLost, ConfigError) as exc:
                self.reconnects += 1
                problem = f"no audio input device '{self.spec}'" \
                    if isinstance(exc, audio_device.NoSuchDevice) else str(exc)
                log.warning("route %s: %s; trying again in %.1f s", self.route, problem,
                            backoff)
                self._stop.wait(backoff)
                backoff = min(backoff * 2, RECONNECT_MAX_S)
                continue
            opened = time.monotonic()
            try:
                self._capture(capture)
            except audio_device.DeviceLost as exc:
                self.reconnects += 1
                log.warning("route %s: %s; reopening", self.route, exc)
                if time.monotonic() - opened >= STEADY_S:
                    backoff = RECONNECT_MIN_S
            finally:
                capture.close()
                self._send(self._cutter.end())
                if capture.dropped:
                    log.warning("route %s: %d audio blocks dropped (the route fell behind)",
                                self.route, capture.dropped)

    def _open(self) -> audio_device.Capture:
        """Finds the device again (it may have come back under another index) and opens it."""
        try:
            device = audio_device.find_device(self.spec)
        except audio_device.NoSuchDevice:
            audio_device.refresh_devices()
            device = audio_device.find_device(self.spec)
        rate = audio_device.capture_rate(device, self.config.sample_rate, self.config.channels)
        capture = audio_device.Capture(device, rate, self.config.channels)
        resampled = f", resampled to {MODEL_RATE} Hz" if rate != MODEL_RATE else ""
        log.info("route %s: capturing from %s at %d Hz, %d channel(s)%s", self.route,
                 device.describe(), rate, self.config.channels, resampled)
        if rate != self.config.sample_rate:
            log.warning("route %s: %s cannot capture at %d Hz; using its own %d Hz",
                        self.route, device.describe(), self.config.sample_rate, rate)
        self._cutter.begin(rate)
        return capture

    def _capture(self, capture: audio_device.Capture) -> None:
        while not self._stop.is_set():
            block = capture.read(READ_TIMEOUT_S)
            if block is not None:
                self._hear(block)

    def _hear(self, block: np.ndarray) -> None:
        """One block of audio into the cutter, muted while the robot speaks, or stopping
        its speech once a new utterance has begun (oricf.gateway.speaking)."""
        speaking = self._speaking
        if speaking is not None and self._while_speaking == "mute" and speaking.muted():
            block = np.zeros_like(block)
        clips = self._cutter.push(block)
        if speaking is not None and self._while_speaking == "barge_in":
            voiced = self._cutter.voiced_s
            if voiced >= self._barge_in_s and not self._barged_in:
                self._barged_in = True
                speaking.interrupt(f"route {self.route}: a new utterance")
            elif voiced == 0:
                self._barged_in = False
        self._send(clips)
