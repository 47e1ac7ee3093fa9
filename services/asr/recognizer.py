"""What a speech-recognition back end is, and the registry that picks one by name.

A back end turns mono float32 audio at its sample rate into text. `model.backend` in
configs/services/asr.yaml names one; `model.options` holds its own settings, checked by its
`Options` schema when the config is loaded. Adding a back end (say Moonshine on
onnxruntime) is one class with this shape plus one line in BACKENDS.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np
from pydantic import Field, ValidationError, ValidationInfo, field_validator

from oricf.config import Schema, format_location
from oricf.services.runtime import ModelInfo

if TYPE_CHECKING:
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


class AsrModelSettings(Schema):
    """`model:` of configs/services/asr.yaml: the back end, its weights, and its own options
    (validated by the back end's Options schema); what a back end is constructed with."""

    backend: str = Field("faster-whisper", description="a name in recognizer.BACKENDS")
    name: str = Field("whisper-tiny-en", description="catalog name in configs/models.yaml")
    threads: int = Field(2, ge=1, le=64, description="CPU threads for inference")
    language: str = Field("en", description="used when a request names no language")
    options: Any = Field(default_factory=dict, validate_default=True,
                         description="the back end's own settings (its Options schema)")

    @field_validator("backend")
    @classmethod
    def _known_backend(cls, value: str) -> str:
        backend_class(value)
        return value

    @field_validator("options")
    @classmethod
    def _backend_options(cls, value: Any, info: ValidationInfo) -> Schema:
        """Checked against the chosen back end's schema, so typos fail at start-up."""
        backend = info.data.get("backend")
        if backend is None:  # the back end itself was refused; that error is enough
            return Schema()
        schema = backend_class(backend).Options
        if isinstance(value, schema):
            return value
        try:
            return schema.model_validate(value or {})
        except ValidationError as exc:
            problems = "; ".join(f"{format_location(e['loc'])}: {e['msg']}" for e in exc.errors())
            raise ValueError(f"{backend} options: {problems}") from None


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
