"""Cuts a stream of 16 kHz audio into utterances by voice activity: the ASR service's
TranscribeStream and the gateway's audio inputs cut speech the same way, with the same settings.

Speech starts at the first window whose probability reaches `threshold`; it goes on while
windows stay above a lower threshold (hysteresis keeps short dips inside a word from
splitting it) and ends after `min_silence_ms` below it. Each utterance keeps
`speech_pad_ms` of audio before and after the speech, because Whisper clips soft word
onsets otherwise. Bursts shorter than `min_speech_ms` are dropped; an utterance reaching
`max_utterance_s` is cut there and the next one starts at once.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from oricf.audio.vad import SAMPLE_RATE, WINDOW, VadStream
from oricf.config import Schema

# Windows scored between two checks of the caller's deadline (about 2 s of audio).
CHECK_EVERY = 64

# Silero's own streaming iterator ends speech at threshold - 0.15.
HYSTERESIS = 0.15


class VadSettings(Schema):
    """How audio is cut into utterances by voice activity (Silero VAD, 32 ms windows at
    16 kHz): the ASR service's `endpointing:` and a gateway audio input's `vad:`."""

    threshold: float = Field(0.5, gt=0, lt=1, description="speech probability that starts speech")
    min_silence_ms: int = Field(
        400, ge=32, le=10_000, description="this much silence ends an utterance")
    speech_pad_ms: int = Field(
        200, ge=0, le=2_000, description="audio kept before and after the detected speech")
    min_speech_ms: int = Field(
        200, ge=0, le=10_000, description="shorter bursts (clicks, coughs) are dropped")
    max_utterance_s: float = Field(
        20.0, gt=1, le=60, description="an utterance this long is cut and transcribed (keep "
                                       "it under the ASR service's audio.max_audio_s)")


class EndpointingSettings(VadSettings):
    """VadSettings and the VAD's own threads: the ASR service's `endpointing:`."""

    vad_threads: int = Field(1, ge=1, le=8, description="onnxruntime threads of the VAD")


@dataclass(frozen=True)
class Utterance:
    samples: np.ndarray   # mono float32 at 16 kHz
    start: int            # sample index in the stream (16 kHz)
    vad_ms: float         # time spent in the VAD since the previous utterance

    @property
    def end(self) -> int:
        return self.start + len(self.samples)


def _ms_to_samples(ms: float) -> int:
    return int(ms * SAMPLE_RATE / 1000)


class Endpointer:
    """push() audio as it arrives and get back the utterances it completes; flush() at the end."""

    def __init__(self, vad: VadStream, settings: VadSettings) -> None:
        self.vad = vad
        self.threshold = settings.threshold
        self.end_threshold = max(settings.threshold - HYSTERESIS, 0.01)
        self.min_silence = _ms_to_samples(settings.min_silence_ms)
        self.pad = _ms_to_samples(settings.speech_pad_ms)
        self.min_speech = _ms_to_samples(settings.min_speech_ms)
        self.max_samples = int(settings.max_utterance_s * SAMPLE_RATE)
        self._pending = np.zeros(0, dtype=np.float32)   # less than a window, not yet scored
        self._position = 0       # stream index of the next window
        self._recent = np.zeros(0, dtype=np.float32)    # audio before speech (for the pad)
        self._speech: list[np.ndarray] | None = None     # windows of the current utterance
        self._start = 0
        self._length = 0
        self._voiced = 0         # samples scored as speech in the current utterance
        self._silence = 0        # trailing samples scored as silence
        self._vad_ms = 0.0

    @property
    def voiced_s(self) -> float:
        """Seconds scored as speech in the utterance still open (0 when none is open): how
        sure it is that someone has started to speak."""
        return self._voiced / SAMPLE_RATE if self._speech is not None else 0.0

    def push(self, samples: np.ndarray, check: Callable[[], None] | None = None
             ) -> list[Utterance]:
        """Utterances the samples complete; check() runs every CHECK_EVERY windows (it raises
        to stop, e.g. when the caller's deadline has passed)."""
        audio = np.concatenate([self._pending, samples.astype(np.float32, copy=False)])
        whole = len(audio) - len(audio) % WINDOW
        self._pending = audio[whole:]
        done: list[Utterance] = []
        for offset in range(0, whole, WINDOW):
            if check is not None and offset % (CHECK_EVERY * WINDOW) == 0:
                check()
            utterance = self._window(audio[offset:offset + WINDOW])
            if utterance is not None:
                done.append(utterance)
        return done

    def flush(self) -> list[Utterance]:
        """Ends the stream: an utterance still open is finished with what has arrived."""
        if self._speech is None:
            return []
        self._speech.append(self._pending)
        self._length += len(self._pending)
        self._pending = np.zeros(0, dtype=np.float32)
        utterance = self._finish()
        return [utterance] if utterance is not None else []

    def _window(self, window: np.ndarray) -> Utterance | None:
        started = time.perf_counter()
        probability = self.vad.probability(window)
        self._vad_ms += (time.perf_counter() - started) * 1e3
        window_start, self._position = self._position, self._position + WINDOW
        cut = None
        if self._speech is None:
            if probability < self.threshold:
                self._recent = self._tail(np.concatenate([self._recent, window]))
                return None
            speech = self._begin(window_start, self._recent)
        elif self._length + WINDOW > self.max_samples:
            # Too long: close it and go on in a new utterance from this window, without a
            # pre-speech pad (that audio is already in the one just closed).
            cut = self._finish()
            speech = self._begin(window_start, window[:0])
        else:
            speech = self._speech
        speech.append(window)
        self._length += WINDOW
        if probability >= self.end_threshold:
            self._voiced += WINDOW
            self._silence = 0
        else:
            self._silence += WINDOW
        if cut is None and self._silence >= self.min_silence:
            return self._finish()
        return cut

    def _begin(self, start: int, preroll: np.ndarray) -> list[np.ndarray]:
        """Opens an utterance at stream index `start`, with `preroll` audio before it."""
        self._speech = [preroll]
        self._length = len(preroll)
        self._start = start - len(preroll)
        self._voiced = 0
        self._silence = 0
        self._recent = self._recent[:0]
        return self._speech

    def _tail(self, audio: np.ndarray) -> np.ndarray:
        """The last `pad` samples (audio[-0:] would be all of it)."""
        return audio[-self.pad:] if self.pad else audio[:0]

    def _finish(self) -> Utterance | None:
        """Closes the current utterance, trimming trailing silence down to the pad."""
        assert self._speech is not None
        audio = np.concatenate(self._speech)
        trim = max(self._silence - self.pad, 0)
        kept = audio[:len(audio) - trim]
        self._recent = self._tail(audio)
        self._speech = None
        if self._voiced < self.min_speech:
            return None
        utterance = Utterance(kept, self._start, self._vad_ms)
        self._vad_ms = 0.0
        return utterance
