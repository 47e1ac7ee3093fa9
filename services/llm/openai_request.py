"""An OpenAI chat completion request -> the same GenerationRequest a gRPC Generate makes.

The question (the last user message), its facts, max_tokens, temperature and stop go
through a GenerateRequest and services/llm/request.py, so they are checked exactly as over
gRPC; facts arrive in the JSON form of oricf.v1.Fact (an extension field, `facts`). What
only a conversation has is added after: the caller's system text, earlier turns, a JSON
answer (response_format), seed and top_p. Fields that would change the answer in ways this
service cannot honour (n > 1, tools, logprobs, image content) are refused, not ignored.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Literal

from google.protobuf import json_format
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from oricf.services.llm.config import JsonSchemaLimits, LlmConfig
from oricf.services.llm.domain import GenerationRequest, JsonOutput
from oricf.services.llm.grammar import check_schema
from oricf.services.llm.request import to_generation_request
from oricf.services.runtime.http.errors import ApiError, InvalidParam
from oricf.v1 import common_pb2, language_pb2

SYSTEM_ROLES = ("system", "developer")


class Message(BaseModel):
    model_config = ConfigDict(strict=True, extra="ignore")
    role: Literal["system", "developer", "user", "assistant", "tool", "function"]
    content: str | list[dict[str, Any]] | None = None
    tool_calls: list[Any] | None = None


class StreamOptions(BaseModel):
    model_config = ConfigDict(strict=True, extra="ignore")
    include_usage: bool = False


class ChatRequest(BaseModel):
    model_config = ConfigDict(strict=True, extra="ignore")
    model: str | None = None
    messages: list[Message] = Field(min_length=1)
    max_tokens: int | None = Field(None, ge=1, le=2**31)
    max_completion_tokens: int | None = Field(None, ge=1, le=2**31)
    temperature: float | None = None
    top_p: float | None = None
    stop: str | list[str] | None = None
    seed: int | None = Field(None, ge=0, le=2**32 - 1)
    stream: bool = False
    stream_options: StreamOptions | None = None
    response_format: dict[str, Any] | None = None
    facts: list[Any] | None = None
    n: int | None = None
    tools: list[Any] | None = None
    functions: list[Any] | None = None
    logprobs: bool | None = None


def parse_chat(data: dict[str, Any]) -> ChatRequest:
    try:
        return ChatRequest.model_validate(data)
    except ValidationError as exc:
        error = exc.errors()[0]
        param = ".".join(str(part) for part in error["loc"]) or None
        raise InvalidParam(f"{param}: {error['msg']}", param=param) from None


def _refuse_unsupported(chat: ChatRequest) -> None:
    if chat.n not in (None, 1):
        raise InvalidParam("n: this service gives one choice per request (n = 1)", param="n")
    if chat.tools or chat.functions:
        raise InvalidParam("tools: this language service calls no tools", param="tools")
    if chat.logprobs:
        raise InvalidParam("logprobs: not available from this service", param="logprobs")


def _text(message: Message, index: int) -> str:
    """A message's text: a string, or text parts joined; images and other parts refused."""
    where = f"messages[{index}]"
    if message.role in ("tool", "function") or message.tool_calls:
        raise InvalidParam(f"{where}: tool messages and tool calls are not supported (this "
                           f"language service calls no tools)", param=f"{where}.role")
    if isinstance(message.content, str):
        return message.content
    parts = []
    for j, part in enumerate(message.content or []):
        kind = part.get("type")
        if kind == "text" and isinstance(part.get("text"), str):
            parts.append(part["text"])
        elif kind == "image_url":
            raise ApiError(400, f"{where}.content[{j}]: image input is not supported: this "
                                f"language service has no vision model; send text only",
                           param=f"{where}.content", code="image_input_not_supported")
        else:
            raise InvalidParam(f"{where}.content[{j}]: content part of type {str(kind)[:40]!r} "
                               f"is not supported; send text parts", param=f"{where}.content")
    return " ".join(parts)


def conversation(messages: list[Message]) -> tuple[str, tuple[tuple[str, str], ...], str]:
    """(system text, earlier (question, answer) turns, the question)."""
    system: list[str] = []
    turns: list[list[str]] = []  # [role, text], consecutive messages of a role joined
    for i, message in enumerate(messages):
        text = _text(message, i)
        if message.role in SYSTEM_ROLES:
            system.append(text)
        elif turns and turns[-1][0] == message.role:
            turns[-1][1] += " " + text
        else:
            turns.append([message.role, text])
    if not turns or turns[-1][0] != "user":
        raise InvalidParam("messages: the last message (after any system message) must be "
                           "the user's question", param="messages")
    if turns[0][0] != "user":
        raise InvalidParam("messages: an assistant message must follow a user message",
                           param="messages")
    history = tuple((turns[k][1], turns[k + 1][1]) for k in range(0, len(turns) - 1, 2))
    return " ".join(system), history, turns[-1][1]


def parse_facts(facts: list[Any] | None) -> list[common_pb2.Fact]:
    parsed = []
    for i, item in enumerate(facts or []):
        if not isinstance(item, dict):
            raise InvalidParam(f"facts[{i}]: a fact is an object such as "
                               f'{{"name": "people_count", "integer": 3}}', param=f"facts[{i}]")
        try:
            parsed.append(json_format.ParseDict(item, common_pb2.Fact()))
        except (json_format.ParseError, ValueError, TypeError) as exc:
            raise InvalidParam(f"facts[{i}]: {str(exc)[:300]}", param=f"facts[{i}]") from None
    return parsed


def json_output(response_format: dict[str, Any] | None,
                limits: JsonSchemaLimits) -> JsonOutput | None:
    kind = (response_format or {}).get("type", "text")
    if kind == "text":
        return None
    if kind == "json_object":
        return JsonOutput()
    if kind == "json_schema":
        spec = response_format.get("json_schema") if response_format else None
        if not isinstance(spec, dict):
            raise InvalidParam("response_format.json_schema: an object with the schema is "
                               "needed", param="response_format.json_schema")
        schema = spec.get("schema")
        return JsonOutput(None if schema is None else
                          check_schema(schema, "response_format.json_schema.schema", limits))
    raise InvalidParam(f"response_format.type: {str(kind)[:40]!r} is not one of text, "
                       f"json_object, json_schema", param="response_format.type")


def _top_p(value: float | None) -> float | None:
    if value is not None and (math.isnan(value) or not 0 < value <= 1):
        raise InvalidParam(f"top_p {value} is out of range (0, 1]", param="top_p")
    return value


def to_generation(chat: ChatRequest, config: LlmConfig) -> GenerationRequest:
    _refuse_unsupported(chat)
    system, history, question = conversation(chat.messages)
    total = len(system) + len(question) + sum(len(q) + len(a) for q, a in history)
    if total > config.limits.max_prompt_chars:
        raise InvalidParam(f"the messages have {total} characters; the limit is "
                           f"{config.limits.max_prompt_chars}", param="messages")
    stop = [chat.stop] if isinstance(chat.stop, str) else chat.stop or []
    request = language_pb2.GenerateRequest(
        prompt=question, facts=parse_facts(chat.facts), stop=stop,
        max_tokens=chat.max_completion_tokens or chat.max_tokens or 0)
    if chat.temperature is not None:
        request.temperature = chat.temperature
    generation = to_generation_request(request, config.generation, config.limits)
    json = json_output(chat.response_format, config.limits.json_schema)
    return replace(generation, system=system, history=history, json=json, seed=chat.seed,
                   top_p=_top_p(chat.top_p))
