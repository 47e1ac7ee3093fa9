"""configs/services/asr.yaml."""

from __future__ import annotations

from pydantic import Field, model_validator

from oricf.audio import EndpointingSettings
from oricf.config import Schema
from oricf.services.asr.recognizer import AsrModelSettings
from oricf.services.runtime import ServiceConfig


class AudioSettings(Schema):
    max_audio_s: float = Field(30.0, gt=0, le=3600, description="longest Transcribe request")
    max_decoded_mb: float = Field(
        32.0, gt=0, le=4096,
        description="most audio one Transcribe request or upload may hold, as 16-bit samples "
                    "at its own rate and channel count (frames x channels x 2 bytes), before "
                    "it is mixed down and resampled; bounds what decoding a small compressed "
                    "file costs")
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
