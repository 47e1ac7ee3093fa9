"""configs/services/asr.yaml."""

from __future__ import annotations

from typing import Any

from pydantic import Field, ValidationError, ValidationInfo, field_validator, model_validator

from oricf.audio import EndpointingSettings
from oricf.config import Schema, format_location
from oricf.services.asr.recognizer import backend_class
from oricf.services.runtime import ServiceConfig


class AsrModelSettings(Schema):
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


class AudioSettings(Schema):
    max_audio_s: float = Field(30.0, gt=0, le=3600, description="longest Transcribe request")
    max_stream_s: float = Field(
        600.0, gt=0, le=86_400, description="most audio one TranscribeStream may carry")


class AsrConfig(ServiceConfig):
    model: AsrModelSettings = AsrModelSettings()
    endpointing: EndpointingSettings = EndpointingSettings()
    audio: AudioSettings = AudioSettings()

    @model_validator(mode="after")
    def _utterance_fits(self) -> AsrConfig:
        if self.endpointing.max_utterance_s > self.audio.max_audio_s:
            raise ValueError("endpointing.max_utterance_s must not exceed audio.max_audio_s")
        return self
