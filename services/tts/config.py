"""configs/services/tts.yaml."""

from __future__ import annotations

import re

from pydantic import Field, model_validator

from oricf.config import Schema
from oricf.services.runtime import ServiceConfig
from oricf.services.tts.text import TextSettings
from oricf.services.tts.voices import VoiceConfig

VOICE_KEY = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"


class AudioSettings(Schema):
    sentence_pause_ms: int = Field(
        200, ge=0, le=5000, description="silence after each sentence but the last")
    max_audio_s: float = Field(
        240.0, gt=0, le=3600,
        description="most audio one request may make: synthesis stops once its audio passes "
                    "this, and the request is refused")


class TtsConfig(ServiceConfig):
    name: str = Field("oricf-tts", description="the model name of the HTTP API (GET /v1/models)")
    default_voice: str = Field(description="the voice of a request that names none")
    voices: dict[str, VoiceConfig] = Field(min_length=1, description="name -> declaration")
    text: TextSettings = TextSettings()
    audio: AudioSettings = AudioSettings()

    @model_validator(mode="after")
    def _voices_named_well(self) -> TtsConfig:
        for key in self.voices:
            if not re.match(VOICE_KEY, key):
                raise ValueError(f"voices: '{key}' is not a voice name (letters, digits, "
                                 f"'_', '.', '-', at most 64)")
        if self.default_voice not in self.voices:
            raise ValueError(f"default_voice: '{self.default_voice}' is not one of the "
                             f"voices ({', '.join(self.voices)})")
        return self
