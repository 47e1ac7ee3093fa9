"""Speech recognition as a runtime service: `oricf serve asr`."""

from __future__ import annotations

from typing import Any

import grpc

from oricf.services import SERVICES
from oricf.services.asr.config import AsrConfig
from oricf.services.asr.model import SpeechModel
from oricf.services.asr.recognizer import backend_class
from oricf.services.asr.servicer import SpeechRecognizerServicer
from oricf.services.runtime import ModelSlot, ServiceParts
from oricf.store import ModelStore
from oricf.v1 import speech_pb2_grpc


def create_model(config: AsrConfig, store: ModelStore) -> SpeechModel:
    settings = config.model
    recognizer = backend_class(settings.backend)(settings, store)
    return SpeechModel(recognizer, config.endpointing, settings.language)


def add_servicer(server: grpc.Server, slot: ModelSlot[SpeechModel], config: AsrConfig) -> None:
    speech_pb2_grpc.add_SpeechRecognizerServicer_to_server(
        SpeechRecognizerServicer(slot, config), server)


def http_routes(slot: ModelSlot[SpeechModel], config: AsrConfig) -> list[Any]:
    """OpenAI's transcription API (docs/openai.md); Starlette is imported only here."""
    from oricf.services.asr.openai_api import routes

    return routes(slot, config)


PARTS = ServiceParts(
    SERVICES["asr"],
    config_schema=AsrConfig,
    create_model=create_model,
    add_servicer=add_servicer,
    http_routes=http_routes,
)
