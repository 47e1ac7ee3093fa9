"""The language model over OpenAI's chat completions API: POST /v1/chat/completions (plain
or streamed as server-sent events) and GET /v1/models, on the model the gRPC side serves.

Requests become the same GenerationRequest as a gRPC Generate (openai_request.py), so the
same question and facts give the same answer either way; the answer goes back in OpenAI's
shapes. The shared HTTP machinery (limits, tokens, errors, metrics) is the runtime's.
"""

from __future__ import annotations

import json
import time
import uuid
from collections.abc import AsyncGenerator, AsyncIterator
from typing import Any

from starlette.requests import Request
from starlette.responses import JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from oricf.services.llm.config import LlmConfig
from oricf.services.llm.domain import Chunk, Finished, GenerationRequest, StillWanted
from oricf.services.llm.model import LlamaModel
from oricf.services.llm.openai_request import ChatRequest, parse_chat, to_generation
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.http.app import check_model, models_route
from oricf.services.runtime.http.calls import Presence, iterate_blocking, read_json, run_blocking
from oricf.services.runtime.http.errors import as_api_error, error_body

SSE_HEADERS = {"Cache-Control": "no-cache", "X-Accel-Buffering": "no"}


def usage(finished: Finished) -> dict[str, Any]:
    return {"prompt_tokens": finished.prompt_tokens,
            "completion_tokens": finished.completion_tokens,
            "total_tokens": finished.prompt_tokens + finished.completion_tokens,
            "prompt_tokens_details": {"cached_tokens": finished.cached_tokens}}


class ChatCompletions:
    """The routes of one service: its model slot, config and served model name."""

    def __init__(self, slot: ModelSlot[LlamaModel], config: LlmConfig) -> None:
        self.slot = slot
        self.config = config
        self.name = config.model.name

    def routes(self) -> list[Route]:
        return [Route("/v1/chat/completions", self.chat, methods=["POST"]),
                models_route(self.name)]

    async def chat(self, request: Request) -> Response:
        chat = parse_chat(await read_json(request))
        model = self.slot.get()
        check_model(chat.model, self.name)
        generation = to_generation(chat, self.config)
        head = {"id": f"chatcmpl-{uuid.uuid4().hex}", "created": int(time.time()),
                "model": self.name, "system_fingerprint": None}
        if chat.stream:
            return await self._stream(model, generation, chat, head)

        def complete(still_wanted: StillWanted) -> dict[str, Any]:
            return _completion(model, generation, still_wanted, head)

        return JSONResponse(await run_blocking(request, complete))

    async def _stream(self, model: LlamaModel, generation: GenerationRequest,
                      chat: ChatRequest, head: dict[str, Any]) -> Response:
        presence = Presence()
        chunks = iterate_blocking(model.generate(generation, presence.still_wanted), presence)
        try:
            # The first token comes before the answer starts, so a refusal (the model is
            # busy, the prompt does not fit) is still an HTTP status, not a stream error.
            first = await anext(chunks)
        except BaseException:
            await chunks.aclose()
            raise
        with_usage = chat.stream_options is not None and chat.stream_options.include_usage
        events = _events(first, chunks, head, with_usage)
        return StreamingResponse(events, media_type="text/event-stream", headers=SSE_HEADERS)


def _completion(model: LlamaModel, generation: GenerationRequest, still_wanted: StillWanted,
                head: dict[str, Any]) -> dict[str, Any]:
    pieces: list[str] = []
    for chunk in model.generate(generation, still_wanted):
        pieces.append(chunk.text)
        if chunk.finished is not None:
            message = {"role": "assistant", "content": "".join(pieces), "refusal": None}
            return {**head, "object": "chat.completion", "choices": [
                {"index": 0, "message": message, "logprobs": None,
                 "finish_reason": chunk.finished.finish_reason}],
                "usage": usage(chunk.finished)}
    raise RuntimeError("the model ended without a final chunk")


def _event(data: dict[str, Any]) -> str:
    return f"data: {json.dumps(data)}\n\n"


def _delta(head: dict[str, Any], delta: dict[str, Any], finish: str | None) -> str:
    return _event({**head, "object": "chat.completion.chunk", "choices": [
        {"index": 0, "delta": delta, "logprobs": None, "finish_reason": finish}]})


async def _events(first: Chunk, rest: AsyncGenerator[Chunk, None], head: dict[str, Any],
                  with_usage: bool) -> AsyncIterator[str]:
    """The answer as OpenAI's chunks: the role, the text as it comes, the finish reason,
    the usage when asked for, and [DONE]. An error mid-way is an `error` event."""
    yield _delta(head, {"role": "assistant", "content": ""}, None)
    chunk: Chunk | None = first
    try:
        while chunk is not None:
            if chunk.text:
                yield _delta(head, {"content": chunk.text}, None)
            if chunk.finished is not None:
                yield _delta(head, {}, chunk.finished.finish_reason)
                if with_usage:
                    yield _event({**head, "object": "chat.completion.chunk", "choices": [],
                                  "usage": usage(chunk.finished)})
                yield "data: [DONE]\n\n"
                return
            chunk = await anext(rest, None)
    except Exception as exc:
        error = as_api_error(exc, 0)
        yield _event(error_body(error.status, error.message, code=error.code))
    finally:
        await rest.aclose()


def routes(slot: ModelSlot[LlamaModel], config: LlmConfig) -> list[Route]:
    return ChatCompletions(slot, config).routes()
