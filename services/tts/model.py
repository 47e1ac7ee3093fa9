"""The speech service's model: every declared voice, loaded before the port reports SERVING,
and text -> checked, normalised sentences -> audio. Knows nothing of gRPC or HTTP."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from oricf.errors import InvalidInput
from oricf.services.runtime import ModelInfo
from oricf.services.tts import text as texts
from oricf.services.tts.config import TtsConfig
from oricf.services.tts.voices import Voice

log = logging.getLogger(__name__)

MIN_SPEED, MAX_SPEED = 0.25, 4.0


@dataclass(frozen=True)
class Job:
    """One request, checked: the voice, the sentences to say and the speed."""

    voice: Voice
    sentences: list[str]
    speed: float


@dataclass(frozen=True)
class SpokenSentence:
    index: int
    text: str
    samples: np.ndarray   # mono int16, the pause after it included
    sample_rate: int
    inference_ms: float
    last: bool

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate


class SynthesisModel:
    def __init__(self, voices: dict[str, Voice], config: TtsConfig) -> None:
        self.voices = voices
        self.config = config
        self.default_voice = config.default_voice

    def load(self) -> None:
        for voice in self.voices.values():
            started = time.perf_counter()
            voice.load()
            log.info("voice %s (%s, %d Hz) ready in %.1f s", voice.name, voice.model,
                     voice.sample_rate, time.perf_counter() - started)

    def close(self) -> None:
        for voice in self.voices.values():
            voice.close()

    def info(self) -> ModelInfo:
        default = self.voices[self.default_voice]
        parameters = {"default_voice": self.default_voice, "voices": ",".join(self.voices),
                      "max_chars": str(self.config.text.max_chars)}
        for name, voice in self.voices.items():
            parameters.update({f"voice.{name}.{k}": v for k, v in voice.describe().items()})
        return ModelInfo(model=default.model, runtime=default.runtime, license=default.license,
                         sha256=default.sha256, providers=["cpu"], parameters=parameters)

    def voice(self, name: str) -> Voice:
        voice = self.voices.get(name or self.default_voice)
        if voice is None:
            raise InvalidInput(f"voice: {name[:64]!r} is not declared here (voices: "
                               f"{', '.join(self.voices)})")
        return voice

    def prepare(self, text: str, voice: str = "", speed: float = 0.0) -> Job:
        """A request's text, voice and speed checked; InvalidInput says what is wrong."""
        chosen = self.voice(voice)
        if speed == 0:
            speed = 1.0
        if not math.isfinite(speed) or not MIN_SPEED <= speed <= MAX_SPEED:
            raise InvalidInput(f"speed: {speed} is outside {MIN_SPEED} to {MAX_SPEED}")
        settings = self.config.text
        normalised = texts.check_spoken(
            texts.normalise(texts.check(text, settings.max_chars), settings.abbreviations),
            settings.max_spoken_chars)
        sentences = texts.sentences(normalised, settings.max_sentence_chars)
        if not sentences:
            raise InvalidInput("text: nothing to say (no letters or digits)")
        return Job(chosen, sentences, speed)

    def speak(self, job: Job, still_wanted: Callable[[], None] = lambda: None
              ) -> Iterator[SpokenSentence]:
        """The job's sentences as audio, one at a time, as each is made.

        still_wanted is called after each piece a voice makes (a sentence, or a part of a
        long one) and stops the work by raising once the caller has gone. A job whose audio
        passes audio.max_audio_s is refused there: its length is known only once made.
        """
        voice = job.voice
        pause = np.zeros(voice.sample_rate * self.config.audio.sentence_pause_ms // 1000,
                         dtype=np.int16)
        made = 0  # samples so far
        limit = int(self.config.audio.max_audio_s * voice.sample_rate)
        for i, sentence in enumerate(job.sentences):
            started = time.perf_counter()
            parts = []
            for piece in voice.pieces(sentence, job.speed):
                made += len(piece)
                if made > limit:
                    raise InvalidInput(self._too_long(job))
                parts.append(piece)
                still_wanted()
            inference_ms = (time.perf_counter() - started) * 1e3
            last = i == len(job.sentences) - 1
            if not last:  # the pause counts too: the audio never passes the limit
                made += len(pause)
                if made > limit:
                    raise InvalidInput(self._too_long(job))
                parts.append(pause)
            samples = np.concatenate(parts) if parts else np.zeros(0, dtype=np.int16)
            yield SpokenSentence(i, sentence, samples, voice.sample_rate, inference_ms, last)

    def _too_long(self, job: Job) -> str:
        limit = self.config.audio.max_audio_s
        return (f"text: at speed {job.speed:g} it makes more than {limit:g} s of audio, this "
                f"service's limit (audio.max_audio_s); send less text or a higher speed")
