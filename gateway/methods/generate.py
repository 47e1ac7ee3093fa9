"""Generate: a prompt template with context -> an answer, on ORICF's language model
(oricf.v1.LanguageModel) or any OpenAI-compatible server (POST /chat/completions: Ollama,
vLLM, llama.cpp's server, ORICF's own with --http-listen). The context is data products,
each with its age; a stale one is left out or sent marked stale, never passed off as
current. Over gRPC they go as typed facts (oricf.v1.Fact); over the OpenAI API, rendered
into a system message (chat.py), with the newest camera frame as an image if asked."""

from __future__ import annotations

import json
import logging
import numbers
from collections.abc import Generator, Iterable, Iterator
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from oricf.config import Schema
from oricf.errors import InvalidInput
from oricf.gateway.components import CallBase, Method, MethodCall, Partial, Skip, Stream
from oricf.gateway.endpoints import Endpoint, GrpcTarget
from oricf.gateway.endpoints.openai import OpenAITarget, chat_completion
from oricf.gateway.methods.base import ServingHealth
from oricf.gateway.methods.chat import ChatTemplates, ImageContext, image_url, messages
from oricf.gateway.methods.sentences import SentenceCutter
from oricf.gateway.products import ProductStore, Reading
from oricf.gateway.values import Record, template_fields
from oricf.v1 import common_pb2, language_pb2, language_pb2_grpc

log = logging.getLogger(__name__)


class ContextConfig(Schema):
    products: list[str] = Field(min_length=1)
    stale: Literal["omit", "mark"] = Field(
        "omit", description="a product older than its max_age_s: left out, or sent marked stale")
    chat: ChatTemplates = Field(
        default_factory=ChatTemplates,
        description="openai: how the facts become a system message")


class GenerateCall(CallBase):
    """oricf.v1.LanguageModel/Generate: a prompt template with context -> answer."""

    method: Literal["Generate"]
    prompt: str = Field("{text}", description="template over the record's fields")
    max_tokens: int = Field(0, ge=0, le=4096)
    temperature: float | None = Field(None, ge=0, le=5)
    stop: list[str] = Field(default_factory=list)
    context: ContextConfig | None = None
    stream: bool = Field(False, description="take the answer as it is produced (GenerateStream, "
                                            "or server-sent events), joined")
    sentences: bool = Field(
        False, description="stream the answer and send each sentence on (field `sentence`) "
                           "as soon as it is complete, e.g. to be spoken while the rest is "
                           "generated")
    image: ImageContext | None = Field(
        None, description="openai: the newest frame of a data product, for a vision-language "
                          "model")

    @field_validator("prompt")
    @classmethod
    def _template(cls, value: str) -> str:
        template_fields(value)  # a malformed template (e.g. an unclosed brace) is refused
        return value


@dataclass(frozen=True)
class Answer:
    answer: str


@dataclass(frozen=True)
class SentencedAnswer:
    answer: str
    sentence: str | None  # each sentence is sent on as it is complete (a Partial)


def context_readings(call: GenerateCall, products: ProductStore) -> list[Reading]:
    """The context's products as they are now (stale ones left out or marked)."""
    return products.context(call.context.products, call.context.stale) if call.context \
        else []


def generate_request(record: Record, call: GenerateCall, products: ProductStore,
                     readings: list[Reading] | None = None) -> language_pb2.GenerateRequest:
    """The gRPC request; `readings` are the context's, read now if not given."""
    try:
        prompt = call.prompt.format_map(record).strip()
    except (KeyError, IndexError, ValueError) as exc:
        raise InvalidInput(f"prompt template {call.prompt!r}: cannot fill {exc}") from None
    if not prompt:
        raise Skip("empty prompt")
    if readings is None:
        readings = context_readings(call, products)
    request = language_pb2.GenerateRequest(prompt=prompt, facts=[fact(r) for r in readings],
                                           max_tokens=call.max_tokens, stop=call.stop)
    if call.temperature is not None:
        request.temperature = call.temperature
    return request


def fact(reading: Reading) -> common_pb2.Fact:
    """A data product as an oricf.v1.Fact: the value in its own type, its age, whether stale.
    A value with no typed form (a dict of counts, a list) goes as JSON text; None, or a
    number that is not finite, as no value (the receiver renders it as unknown)."""
    message = common_pb2.Fact(name=reading.name, age_s=reading.age_s, stale=reading.stale)
    value = reading.value
    if value is None:
        pass
    elif isinstance(value, (bool, np.bool_)):
        message.flag = bool(value)
    elif isinstance(value, numbers.Integral) and -2**63 <= int(value) < 2**63:
        message.integer = int(value)
    elif isinstance(value, numbers.Real):
        if np.isfinite(float(value)):
            message.number = float(value)
    elif isinstance(value, str):
        message.text = value
    else:
        message.text = json.dumps(value, default=str)
    return message


def facts_text(facts: Iterable[common_pb2.Fact]) -> str:
    """Facts on one line for logs: `people_count=3 (1.2 s)`, `people_count=3 (stale, 12.0 s)`."""
    parts = []
    for f in facts:
        kind = f.WhichOneof("value")
        value = repr(getattr(f, kind)) if kind else "(no value)"
        notes = [*(["stale"] if f.stale else []),
                 *([f"{f.age_s:.1f} s"] if f.HasField("age_s") else [])]
        parts.append(f"{f.name}={value}" + (f" ({', '.join(notes)})" if notes else ""))
    return ", ".join(parts) or "none"


class Generate(MethodCall[GenerateCall]):
    """A route's Generate: one call per protocol the endpoint's targets speak, whole or
    (sentences: true) cut into sentences as they come."""

    result = Answer  # SentencedAnswer when the call cuts sentences (result_type)

    def __init__(self, call: GenerateCall, endpoint: Endpoint, products: ProductStore
                 ) -> None:
        super().__init__(call, endpoint, products)
        self._text_only = _TextOnly(endpoint.name)

    @classmethod
    def result_type(cls, call: GenerateCall) -> type:
        return SentencedAnswer if call.sentences else Answer

    def execute(self, record: Record) -> Answer | Stream:
        readings = context_readings(self.call, self.products)
        request = generate_request(record, self.call, self.products, readings)
        if log.isEnabledFor(logging.DEBUG):
            log.debug("Generate prompt %r facts %s", request.prompt, facts_text(request.facts))
        if self.call.sentences:
            return _sentences(self.endpoint.run({
                "grpc": partial(self._pieces_over_grpc, request),
                "openai": partial(self._pieces_over_openai, request, readings)}))
        text = self.endpoint.run({"grpc": partial(self._over_grpc, request),
                                  "openai": partial(self._over_openai, request, readings)})
        return Answer(text.strip())

    def _over_grpc(self, request: language_pb2.GenerateRequest, target: GrpcTarget,
                   timeout: float) -> str:
        if self.call.image is not None:
            self._text_only.warn(target.address)
        if not self.call.stream:
            return str(target.invoke("Generate", request, timeout).text)
        return "".join(r.text for r in target.invoke("GenerateStream", request, timeout))

    def _over_openai(self, request: language_pb2.GenerateRequest, readings: list[Reading],
                     target: OpenAITarget, timeout: float) -> str:
        call = self.call
        image = image_url(self.products, call.image) if call.image else None
        templates = call.context.chat if call.context else ChatTemplates()
        body: dict[str, Any] = {"messages": messages(request.prompt, readings, templates, image)}
        if call.max_tokens:
            body["max_tokens"] = call.max_tokens
        if call.temperature is not None:
            body["temperature"] = call.temperature
        if call.stop:
            body["stop"] = call.stop
        return chat_completion(target, body, timeout, call.stream)

    def _pieces_over_grpc(self, request: language_pb2.GenerateRequest, target: GrpcTarget,
                          timeout: float) -> Iterator[str]:
        if self.call.image is not None:
            self._text_only.warn(target.address)
        replies = target.invoke("GenerateStream", request, timeout)
        # The first piece is awaited here, so that a server that is down or busy is
        # retried or failed over like any call; the rest streams.
        first = next(replies, None)
        return _pieces(replies, first)

    def _pieces_over_openai(self, request: language_pb2.GenerateRequest,
                            readings: list[Reading], target: OpenAITarget, timeout: float
                            ) -> Iterator[str]:
        """The whole answer as one piece (the OpenAI API's stream is joined)."""
        return iter([self._over_openai(request, readings, target, timeout)])


def _pieces(replies: Any, first: Any) -> Iterator[str]:
    try:
        reply = first
        while reply is not None:
            yield str(reply.text)
            reply = next(replies, None)
    finally:
        replies.cancel()  # stopped early (barge-in): the model stops generating


def _sentences(pieces: Iterator[str]
               ) -> Generator[Partial | SentencedAnswer, None, None]:
    """Each sentence as soon as it is complete, then the whole answer."""
    cutter = SentenceCutter()
    text = []
    try:
        for piece in pieces:
            text.append(piece)
            for sentence in cutter.push(piece):
                yield Partial({"sentence": sentence})
    finally:
        close = getattr(pieces, "close", None)
        if close is not None:
            close()
    for sentence in cutter.flush():
        yield Partial({"sentence": sentence})
    yield SentencedAnswer("".join(text).strip(), None)


class _TextOnly:
    """Says once that a text-only server (ORICF's gRPC language service, e.g. a fallback)
    answers without the image."""

    def __init__(self, endpoint: str) -> None:
        self._endpoint = endpoint
        self._warned = False

    def warn(self, address: str) -> None:
        if not self._warned:
            self._warned = True
            log.warning("endpoint %s: %s takes no images; asking it without the frame",
                        self._endpoint, address)


def reads(call: GenerateCall) -> dict[str, set[str]]:
    """The record fields the prompt template names, by the key that names them."""
    return {"prompt": template_fields(call.prompt)}


def products(call: GenerateCall) -> dict[str, list[str]]:
    return {"context.products": call.context.products if call.context else [],
            "image.product": [call.image.product] if call.image else []}


METHOD = Method("Generate", GenerateCall, "oricf.v1.LanguageModel",
                language_pb2_grpc.LanguageModelStub, ServingHealth("oricf.v1.LanguageModel"),
                Generate, reads=reads, products=products, answers=True,
                protocols=frozenset({"grpc", "openai"}), rank=2)
