"""What a voice engine is, and which engine each `voices:` entry names.

A voice is a declaration in configs/services/tts.yaml: a name, an engine and the engine's own
keys (a discriminated union, so a key of another engine is refused by the schema). An engine
turns one normalised sentence into mono int16 samples at its sample rate.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Annotated, Protocol

import numpy as np
from pydantic import Field

from oricf.services.tts.espeak import EspeakVoice, EspeakVoiceConfig
from oricf.services.tts.piper import PiperVoice, PiperVoiceConfig

if TYPE_CHECKING:
    from oricf.store import ModelStore

VoiceConfig = Annotated[PiperVoiceConfig | EspeakVoiceConfig, Field(discriminator="engine")]


class Voice(Protocol):
    name: str
    model: str          # what speaks: a catalog name, or espeak-ng:VOICE
    sample_rate: int    # known once loaded
    runtime: str
    license: str
    sha256: str

    def load(self) -> None:
        """Loads and warms up; heavy imports belong here."""

    def close(self) -> None: ...

    def describe(self) -> dict[str, str]:
        """Its settings in force, for GetModelInfo."""
        ...

    def speak(self, sentence: str, speed: float) -> np.ndarray:
        """Mono int16 samples of one normalised sentence; speed 1.0 is the voice's own."""
        ...

    def pieces(self, sentence: str, speed: float) -> Iterator[np.ndarray]:
        """The same samples in pieces, each made when it is asked for: a sentence that costs
        much (a long one at a low speed, letters of a script the voice spells out) comes in
        parts of bounded work and memory, and the caller may stop between them."""
        ...


def build_voice(name: str, config: PiperVoiceConfig | EspeakVoiceConfig,
                store: ModelStore) -> Voice:
    if isinstance(config, PiperVoiceConfig):
        return PiperVoice(name, config, store)
    return EspeakVoice(name, config)
