"""Transcribe: an utterance -> its transcript, on ORICF's speech recognizer
(oricf.v1.SpeechRecognizer). An utterance with no words ends the route there (Skip)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from oricf.errors import InvalidInput
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.methods.base import CallBase, Invoke, Method, Skip, health_check
from oricf.gateway.products import ProductStore
from oricf.gateway.values import AudioClip, Record
from oricf.v1 import speech_pb2, speech_pb2_grpc


class TranscribeCall(CallBase):
    """oricf.v1.SpeechRecognizer/Transcribe: audio -> transcript, duration_s."""

    method: Literal["Transcribe"]
    language: str = ""


@dataclass(frozen=True)
class Transcript:
    transcript: str
    duration_s: float


def transcribe_request(record: Record, call: TranscribeCall) -> speech_pb2.TranscribeRequest:
    clip = record.get("audio")
    if not isinstance(clip, AudioClip):
        raise InvalidInput("Transcribe needs an audio input")
    return speech_pb2.TranscribeRequest(audio=clip.to_proto(), language=call.language)


def transcript(response: speech_pb2.Transcript) -> Transcript:
    text = response.text.strip()
    if not text:
        raise Skip("the audio transcribed to no words")
    return Transcript(text, response.duration_s)


def bind(call: TranscribeCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    return lambda record: transcript(
        endpoint.call("Transcribe", transcribe_request(record, call)))


def result(call: Any) -> type:
    return Transcript


METHOD = Method("Transcribe", TranscribeCall, "oricf.v1.SpeechRecognizer",
                speech_pb2_grpc.SpeechRecognizerStub, health_check("oricf.v1.SpeechRecognizer"),
                result, bind)
