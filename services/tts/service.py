"""Speech synthesis as a runtime service: `oricf serve tts`."""

from __future__ import annotations

from typing import Any

import grpc

from oricf.services import SERVICES
from oricf.services.runtime import ModelSlot, ServiceParts
from oricf.services.tts.config import TtsConfig
from oricf.services.tts.model import SynthesisModel
from oricf.services.tts.servicer import SpeechSynthesizerServicer
from oricf.services.tts.voices import build_voice
from oricf.store import ModelStore
from oricf.v1 import synthesis_pb2_grpc


def create_model(config: TtsConfig, store: ModelStore) -> SynthesisModel:
    voices = {name: build_voice(name, voice, store) for name, voice in config.voices.items()}
    return SynthesisModel(voices, config)


def add_servicer(server: grpc.Server, slot: ModelSlot[SynthesisModel], config: TtsConfig) -> None:
    synthesis_pb2_grpc.add_SpeechSynthesizerServicer_to_server(
        SpeechSynthesizerServicer(slot), server)


def http_routes(slot: ModelSlot[SynthesisModel], config: TtsConfig) -> list[Any]:
    """OpenAI's speech API (docs/openai.md); Starlette is imported only here."""
    from oricf.services.tts.openai_api import routes

    return routes(slot, config)


PARTS = ServiceParts(
    SERVICES["tts"],
    config_schema=TtsConfig,
    create_model=create_model,
    add_servicer=add_servicer,
    http_routes=http_routes,
)
