"""Synthesize: a text template -> speech, on ORICF's speech synthesizer
(oricf.v1.SpeechSynthesizer). The call is `SynthesizeStream`: the service sends the audio
sentence by sentence as it makes it, and each sentence's audio goes on to the route's
outputs at once (a speaker starts to play the first sentence while the next is being made).
The record then gains `spoken`, the text as the service normalised and spoke it.

Speech asked for before a barge-in is dropped wherever it is (oricf.gateway.speaking), so
each piece carries the time it was asked for.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Generator
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal

from pydantic import Field, field_validator

from oricf.audio import check_format
from oricf.errors import InvalidInput
from oricf.gateway.components import CallBase, Method, MethodCall, Partial, Skip, Stream
from oricf.gateway.endpoints import GrpcTarget
from oricf.gateway.methods.base import ServingHealth
from oricf.gateway.values import Record, SpokenAudio, template_fields
from oricf.logs import quoted
from oricf.v1 import synthesis_pb2, synthesis_pb2_grpc

log = logging.getLogger(__name__)


class SynthesizeCall(CallBase):
    """oricf.v1.SpeechSynthesizer/SynthesizeStream: text -> speech (sentence by sentence),
    spoken."""

    method: Literal["Synthesize"]
    text: str = Field("{value}", description="template over the record's fields")
    voice: str = Field("", description="a voice the service declares; empty: its default")
    speed: float = Field(1.0, ge=0.25, le=4.0)

    @field_validator("text")
    @classmethod
    def _template(cls, value: str) -> str:
        template_fields(value)
        return value


@dataclass(frozen=True)
class Speech:
    speech: SpokenAudio | None  # each sentence's audio is sent on as it comes (a Partial)
    spoken: str


def synthesize_request(record: Record, call: SynthesizeCall
                       ) -> synthesis_pb2.SynthesizeRequest:
    try:
        text = call.text.format_map(record).strip()
    except (KeyError, IndexError, ValueError) as exc:
        raise InvalidInput(f"text template {call.text!r}: cannot fill {exc}") from None
    if not text:
        raise Skip("nothing to say")
    return synthesis_pb2.SynthesizeRequest(text=text, voice=call.voice,
                                           encoding="pcm_s16le", speed=call.speed)


def spoken_audio(reply: synthesis_pb2.SynthesizedAudio, asked_at: float) -> SpokenAudio:
    audio = reply.audio
    if audio.encoding not in ("", "pcm_s16le"):
        raise InvalidInput(f"the synthesizer sent {quoted(audio.encoding)} audio, not "
                           f"pcm_s16le")
    check_format(audio.sample_rate, audio.channels or 1)
    if len(audio.data) % (2 * max(audio.channels, 1)):
        raise InvalidInput("the synthesizer sent a partial sample")
    return SpokenAudio(bytes(audio.data), audio.sample_rate, audio.channels or 1,
                       text=reply.text, asked_at=asked_at)


class Synthesize(MethodCall[SynthesizeCall]):
    """A route's Synthesize: SynthesizeStream, each sentence's audio handed on as it comes."""

    result = Speech

    def execute(self, record: Record) -> Stream:
        request = synthesize_request(record, self.call)
        asked_at = time.monotonic()
        replies, first = self.endpoint.run({"grpc": partial(self._first_over_grpc, request)})
        return _stream(replies, first, asked_at)

    @staticmethod
    def _first_over_grpc(request: synthesis_pb2.SynthesizeRequest, target: GrpcTarget,
                         timeout: float) -> tuple[Any, Any]:
        """The stream and its first reply: awaited here, so that a server that is down or
        busy is retried or failed over like any call; the rest streams."""
        replies = target.invoke("SynthesizeStream", request, timeout)
        return replies, next(replies, None)


def _stream(replies: Any, first: Any, asked_at: float
            ) -> Generator[Partial | Speech, None, None]:
    spoken = []
    try:
        reply = first
        while reply is not None:
            audio = spoken_audio(reply, asked_at)
            spoken.append(audio.text)
            if audio.pcm:
                yield Partial({"speech": audio})
            reply = None if reply.last else next(replies, None)
    finally:
        replies.cancel()  # stopped early (barge-in): the service stops synthesizing
    yield Speech(None, " ".join(t for t in spoken if t))


def reads(call: SynthesizeCall) -> dict[str, set[str]]:
    return {"text": template_fields(call.text)}


METHOD = Method("Synthesize", SynthesizeCall, "oricf.v1.SpeechSynthesizer",
                synthesis_pb2_grpc.SpeechSynthesizerStub,
                ServingHealth("oricf.v1.SpeechSynthesizer"), Synthesize, reads=reads,
                speaks=True, rank=4)
