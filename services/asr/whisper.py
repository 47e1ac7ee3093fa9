"""Whisper on CTranslate2 through faster-whisper, weights from the model store only.

The defaults favour latency for short spoken queries: greedy decoding (beam 1), one
temperature (no fallback re-decoding), no timestamps, no conditioning on earlier text, no
internal VAD (the stream does its own endpointing), and a short encoder window for short
audio (short_window.py). `oricf bench asr` measures them.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import Field

from oricf.config import Schema
from oricf.errors import InvalidInput, NotReady
from oricf.services.asr.recognizer import AsrModelSettings, Recognition
from oricf.services.asr.short_window import ShortWindowDecoder
from oricf.services.runtime import ModelInfo

if TYPE_CHECKING:
    from oricf.store import ModelStore

log = logging.getLogger(__name__)

WEIGHTS = "model.bin"


class WhisperOptions(Schema):
    device: Literal["cpu", "cuda", "auto"] = "cpu"
    compute_type: str = Field("int8", description="int8, int8_float32, float32, float16...")
    beam_size: int = Field(1, ge=1, le=16, description="1: greedy decoding (fastest)")
    temperature: float = Field(0.0, ge=0, le=1, description="0: deterministic")
    without_timestamps: bool = True
    condition_on_previous_text: bool = False
    vad_filter: bool = Field(False, description="faster-whisper's own VAD on unary requests")
    no_speech_threshold: float | None = Field(0.6, ge=0, le=1)
    initial_prompt: str | None = Field(None, description="words to bias towards, e.g. a robot's")
    short_window: bool = Field(
        True, description="encode short audio in a window shorter than 30 s (short_window.py); "
                          "used with temperature 0 and without vad_filter")
    min_window_s: float = Field(10.0, ge=5, le=30, description="shortest such window")


class WhisperRecognizer:
    """The faster-whisper back end: load(), transcribe(), close(), info()."""

    Options = WhisperOptions
    sample_rate = 16000

    def __init__(self, settings: AsrModelSettings, store: ModelStore) -> None:
        self.settings = settings
        self.options: WhisperOptions = settings.options
        entry = store.entry(settings.name)
        self.folder = store.path(settings.name, WEIGHTS).parent
        self.license = entry.license
        self.sha256 = next(f.sha256 for f in entry.files if f.name == WEIGHTS)
        self._model: Any = None
        self._short: dict[str, ShortWindowDecoder] = {}
        self._runtime = "ctranslate2"

    def load(self) -> None:
        import ctranslate2
        import faster_whisper

        # faster-whisper logs every request at INFO; this service logs requests at DEBUG.
        logging.getLogger("faster_whisper").setLevel(logging.WARNING)
        o = self.options
        self._model = faster_whisper.WhisperModel(
            str(self.folder), device=o.device, compute_type=o.compute_type,
            cpu_threads=self.settings.threads, local_files_only=True)
        self._runtime = (f"ctranslate2 {ctranslate2.__version__} "
                         f"(faster-whisper {faster_whisper.__version__})")
        # The first call allocates CTranslate2's buffers: pay for it before serving.
        self.transcribe(np.zeros(self.sample_rate, dtype=np.float32), self.settings.language)

    def close(self) -> None:
        self._model = None
        self._short.clear()

    def languages(self) -> list[str]:
        model = self._model
        return list(model.supported_languages) if model is not None else []

    def info(self) -> ModelInfo:
        o = self.options
        parameters = {"backend": "faster-whisper", "threads": str(self.settings.threads),
                      **{k: str(v) for k, v in o.model_dump().items() if v is not None}}
        return ModelInfo(model=self.settings.name, runtime=self._runtime, providers=[o.device],
                         license=self.license, sha256=self.sha256, parameters=parameters)

    def transcribe(self, samples: np.ndarray, language: str) -> Recognition:
        model = self._model
        if model is None:
            raise NotReady("the speech model is not loaded")
        if language not in model.supported_languages:
            raise InvalidInput(f"language '{language}' is not supported by {self.settings.name} "
                               f"(supported: {', '.join(model.supported_languages[:12])}"
                               f"{'...' if len(model.supported_languages) > 12 else ''})")
        started = time.perf_counter()
        text = None
        o = self.options
        if o.short_window and o.temperature == 0 and not o.vad_filter:
            text = self._short_decoder(language).decode(samples)
        if text is None:
            text = self._full_window(samples, language)
        if not any(c.isalnum() for c in text):  # "." or "..." from silence or noise
            text = ""
        elapsed_ms = (time.perf_counter() - started) * 1e3
        return Recognition(text=text, language=language,
                           duration_s=len(samples) / self.sample_rate,
                           timings_ms={"inference_ms": elapsed_ms})

    def _full_window(self, samples: np.ndarray, language: str) -> str:
        o = self.options
        segments, _info = self._model.transcribe(
            samples, language=language, beam_size=o.beam_size, temperature=o.temperature,
            without_timestamps=o.without_timestamps,
            condition_on_previous_text=o.condition_on_previous_text, vad_filter=o.vad_filter,
            no_speech_threshold=o.no_speech_threshold, initial_prompt=o.initial_prompt)
        # Segments are produced lazily: decoding happens while they are read.
        return "".join(segment.text for segment in segments).strip()

    def _short_decoder(self, language: str) -> ShortWindowDecoder:
        decoder = self._short.get(language)
        if decoder is None:  # a race builds it twice at worst: harmless
            o = self.options
            decoder = ShortWindowDecoder(self._model, language, o.beam_size, o.min_window_s,
                                         o.no_speech_threshold, o.initial_prompt)
            self._short[language] = decoder
        return decoder
