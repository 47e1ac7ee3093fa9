"""What a speech-recognition back end is, and the registry that picks one by name.

A back end turns mono float32 audio at its sample rate into text. `model.backend` in
configs/services/asr.yaml names one; `model.options` holds its own settings, checked by its
`Options` schema when the config is loaded. Adding a back end (say Moonshine on
onnxruntime) is one class with this shape plus one line in BACKENDS.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Protocol

import numpy as np

from oricf.config import Schema
from oricf.services.runtime import ModelInfo

if TYPE_CHECKING:
    from oricf.services.asr.config import AsrModelSettings
    from oricf.store import ModelStore

# backend name -> "module:class"; the module is imported only when that back end is chosen.
BACKENDS = {
    "faster-whisper": "oricf.services.asr.whisper:WhisperRecognizer",
}


@dataclass
class Recognition:
    """One transcript, and where the back end's time went (milliseconds)."""

    text: str
    language: str
    duration_s: float
    timings_ms: dict[str, float] = field(default_factory=dict)


class Recognizer(Protocol):
    Options: ClassVar[type[Schema]]   # schema of model.options for this back end
    sample_rate: int

    def __init__(self, settings: AsrModelSettings, store: ModelStore) -> None: ...

    def load(self) -> None:
        """Loads the weights and warms up; heavy imports belong here."""

    def close(self) -> None: ...

    def info(self) -> ModelInfo: ...

    def languages(self) -> list[str]:
        """Language codes the loaded model can transcribe."""
        ...

    def transcribe(self, samples: np.ndarray, language: str) -> Recognition:
        """Text of mono float32 samples at sample_rate."""
        ...


def backend_class(name: str) -> type[Recognizer]:
    """The class registered for a back end name; ValueError names the known ones."""
    try:
        target = BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown back end '{name}' (known: {', '.join(BACKENDS)})") from None
    module, attribute = target.split(":")
    cls: type[Recognizer] = getattr(importlib.import_module(module), attribute)
    return cls
