"""oricf.v1.LanguageModel: turns requests into domain values, calls the model, and back."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import grpc

from oricf.services.llm.config import LlmConfig
from oricf.services.llm.domain import Chunk, Finished, GenerationRequest, StillWanted
from oricf.services.llm.model import LlamaModel
from oricf.services.llm.request import to_generation_request
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.errors import check_wanted
from oricf.services.runtime.info import model_info_response
from oricf.v1 import common_pb2, language_pb2, language_pb2_grpc

log = logging.getLogger(__name__)


def still_wanted(context: grpc.ServicerContext) -> StillWanted:
    """The model's between-tokens check: stop as soon as the caller cannot use the answer."""

    return lambda: check_wanted(context, "while generating; generation stopped",
                                "the caller went away; generation stopped")


class LanguageModelServicer(language_pb2_grpc.LanguageModelServicer):
    def __init__(self, slot: ModelSlot[LlamaModel], config: LlmConfig) -> None:
        self.slot = slot
        self.config = config

    def Generate(self, request: language_pb2.GenerateRequest,
                 context: grpc.ServicerContext) -> language_pb2.GenerateResponse:
        pieces: list[str] = []
        for chunk in self._chunks(request, context):
            pieces.append(chunk.text)
            if chunk.finished is not None:
                return _response("".join(pieces), chunk.finished)
        raise RuntimeError("the model ended without a final chunk")

    def GenerateStream(self, request: language_pb2.GenerateRequest,
                       context: grpc.ServicerContext) -> Iterator[language_pb2.GenerateResponse]:
        for chunk in self._chunks(request, context):
            if chunk.finished is not None:
                yield _response(chunk.text, chunk.finished)
            elif chunk.text:
                yield language_pb2.GenerateResponse(text=chunk.text)

    def GetModelInfo(self, request: common_pb2.GetModelInfoRequest,
                     context: grpc.ServicerContext) -> common_pb2.GetModelInfoResponse:
        return model_info_response("llm", self.slot)

    def _chunks(self, request: language_pb2.GenerateRequest,
                context: grpc.ServicerContext) -> Iterator[Chunk]:
        model = self.slot.get()
        generation: GenerationRequest = to_generation_request(
            request, self.config.generation, self.config.limits)
        return model.generate(generation, still_wanted(context))


def _response(text: str, finished: Finished) -> language_pb2.GenerateResponse:
    return language_pb2.GenerateResponse(
        text=text,
        finish_reason=finished.finish_reason,
        prompt_tokens=finished.prompt_tokens,
        completion_tokens=finished.completion_tokens,
        timings=common_pb2.Timings(
            preprocess_ms=finished.preprocess_ms, inference_ms=finished.inference_ms,
            total_ms=finished.total_ms, first_token_ms=finished.first_token_ms,
            queue_ms=finished.queue_ms),
    )
