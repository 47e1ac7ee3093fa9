"""Transcribe: an utterance -> its transcript, on ORICF's speech recognizer
(oricf.v1.SpeechRecognizer) or any OpenAI-compatible server (POST /audio/transcriptions,
the utterance as a WAV file: faster-whisper-server, LocalAI, vLLM, ORICF's own with
--http-listen). An utterance with no words ends the route there (Skip)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from oricf.audio import encode_wav
from oricf.errors import InvalidInput
from oricf.gateway.components import CallBase, Invoke, Method, Skip
from oricf.gateway.endpoints import Endpoint, GrpcTarget
from oricf.gateway.endpoints.openai import OpenAITarget, transcription
from oricf.gateway.methods.base import health_check
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


def utterance(record: Record) -> AudioClip:
    clip = record.get("audio")
    if not isinstance(clip, AudioClip):
        raise InvalidInput("Transcribe needs an audio input")
    return clip


def bind(call: TranscribeCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    def invoke(record: Record) -> Transcript:
        clip = utterance(record)

        def over_grpc(target: GrpcTarget, timeout: float) -> str:
            request = speech_pb2.TranscribeRequest(audio=clip.to_proto(), language=call.language)
            return str(target.invoke("Transcribe", request, timeout).text)

        def over_openai(target: OpenAITarget, timeout: float) -> str:
            samples = np.frombuffer(clip.pcm, "<i2").reshape(-1, clip.channels)
            return transcription(target, encode_wav(samples, clip.sample_rate),
                                     call.language, timeout)

        text = endpoint.run({"grpc": over_grpc, "openai": over_openai}).strip()
        if not text:
            raise Skip("the audio transcribed to no words")
        return Transcript(text, clip.duration_s)

    return invoke


def result(call: Any) -> type:
    return Transcript


METHOD = Method("Transcribe", TranscribeCall, "oricf.v1.SpeechRecognizer",
                speech_pb2_grpc.SpeechRecognizerStub, health_check("oricf.v1.SpeechRecognizer"),
                result, bind, protocols=frozenset({"grpc", "openai"}), hears=True, rank=1)
