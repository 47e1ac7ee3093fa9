"""Audio inputs (`input: {audio: ...}`): utterances from a microphone or any audio device,
or from a WAV file, each one sent to the route as an AudioClip (16 kHz mono), cut by voice
activity. This module declares the input (its settings and COMPONENT); what captures, reads
and cuts the audio is audio_source.py, imported when a pipeline opens an audio input, so
that loading the pipeline schema loads no audio device or VAD.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator

from oricf.audio import VadSettings
from oricf.config import Schema, resolve_path
from oricf.gateway.components import ComponentContext
from oricf.gateway.sources.base import OnEnd, Source, SourceKind, Submit


class VadConfig(VadSettings):
    """How an audio input is cut into utterances: the same settings as the ASR service's
    `endpointing:`."""


class AudioInput(Schema):
    audio: str | None = Field(
        None, description="utterances from an audio device ('default', a name or an index) "
                          "or a .wav file, cut by voice activity")
    sample_rate: int = Field(16000, gt=0, le=384_000, description="audio: Hz")
    channels: int = Field(1, ge=1, le=32, description="audio: interleaved channels")
    vad: VadConfig | None = Field(None, description="audio: voice activity settings")
    while_speaking: Literal["mute", "barge_in"] | None = Field(
        None, description="audio, while a speaker output plays: mute (hear silence, so the "
                          "robot never hears itself; the default) or barge_in (a new "
                          "utterance stops the speech; for a headset or an echo-cancelled "
                          "microphone)")

    @field_validator("audio", mode="before")
    @classmethod
    def _wav_beside_yaml(cls, value: Any, info: Any) -> Any:
        """A .wav file resolves against the YAML file like every path; a device name stays."""
        if not isinstance(value, str) or not value.lower().endswith(".wav"):
            return value
        return str(resolve_path(value, info))


def stray(config: Any) -> str | None:
    given = [key for key in ("vad", "while_speaking") if getattr(config, key) is not None]
    return f"{', '.join(given)}: only with audio" if given else None


def open_source(route: str, config: Any, submit: Submit, on_end: OnEnd,
                context: ComponentContext) -> Source:
    from oricf.gateway.sources.audio_source import AudioSource  # a pipeline opens one

    return AudioSource(route, config, submit, on_end, context.speaking)


COMPONENT = SourceKind("audio", AudioInput, lambda config: "audio", open_source, stray=stray,
                       rank=3)
