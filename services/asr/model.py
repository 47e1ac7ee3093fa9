"""The speech service's model: a recognizer back end plus the streaming voice-activity detector.

This is what the runtime loads before the port reports SERVING and closes on shutdown.
Knows nothing of gRPC.
"""

from __future__ import annotations

import logging

import numpy as np

from oricf.audio import EndpointingSettings
from oricf.audio.endpointing import Endpointer
from oricf.audio.vad import ASSET, SAMPLE_RATE, SileroVad
from oricf.errors import ConfigError
from oricf.services.asr.recognizer import Recognition, Recognizer
from oricf.services.runtime import ModelInfo

log = logging.getLogger(__name__)


class SpeechModel:
    def __init__(self, recognizer: Recognizer, endpointing: EndpointingSettings,
                 default_language: str) -> None:
        if recognizer.sample_rate != SAMPLE_RATE:  # streamed utterances come cut at the VAD's rate
            raise ConfigError(f"the speech back end takes {recognizer.sample_rate} Hz audio; "
                              f"streaming needs {SAMPLE_RATE} Hz")
        self.recognizer = recognizer
        self.endpointing = endpointing
        self.default_language = default_language
        self.vad = SileroVad(endpointing.vad_threads)

    @property
    def sample_rate(self) -> int:
        return self.recognizer.sample_rate

    def load(self) -> None:
        self.vad.load()
        self.recognizer.load()
        log.info("speech model languages: %s", ", ".join(self.recognizer.languages()[:8]))

    def close(self) -> None:
        self.recognizer.close()
        self.vad.close()

    def info(self) -> ModelInfo:
        info = self.recognizer.info()
        e = self.endpointing
        parameters = {
            **info.parameters,
            "language": self.default_language,
            "vad": f"{ASSET} ({self.vad.runtime})",
            "vad_threshold": str(e.threshold),
            "vad_min_silence_ms": str(e.min_silence_ms),
            "vad_speech_pad_ms": str(e.speech_pad_ms),
            "vad_max_utterance_s": str(e.max_utterance_s),
        }
        return ModelInfo(model=info.model, runtime=info.runtime, providers=info.providers,
                         license=info.license, sha256=info.sha256, parameters=parameters)

    def infer(self, samples: np.ndarray, language: str = "") -> Recognition:
        """Text of mono float32 samples at sample_rate; language "" means the default."""
        return self.recognizer.transcribe(samples, language or self.default_language)

    def endpointer(self) -> Endpointer:
        """A fresh endpointer (with its own VAD state) for one audio stream."""
        return Endpointer(self.vad.stream(), self.endpointing)
