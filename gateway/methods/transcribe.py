"""Transcribe: an utterance -> its transcript, on ORICF's speech recognizer
(oricf.v1.SpeechRecognizer) or any OpenAI-compatible server (POST /audio/transcriptions,
the utterance as a WAV file: faster-whisper-server, LocalAI, vLLM, ORICF's own with
--http-listen). An utterance with no words ends the route there (Skip)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Literal

import numpy as np

from oricf.audio import encode_wav
from oricf.errors import InvalidInput
from oricf.gateway.components import CallBase, Method, MethodCall, Skip
from oricf.gateway.endpoints import GrpcTarget
from oricf.gateway.endpoints.openai import OpenAITarget, transcription
from oricf.gateway.methods.base import ServingHealth
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


class Transcribe(MethodCall[TranscribeCall]):
    """A route's Transcribe: one call per protocol the endpoint's targets speak."""

    result = Transcript

    def execute(self, record: Record) -> Transcript:
        clip = utterance(record)
        text = self.endpoint.run({"grpc": partial(self._over_grpc, clip),
                                  "openai": partial(self._over_openai, clip)}).strip()
        if not text:
            raise Skip("the audio transcribed to no words")
        return Transcript(text, clip.duration_s)

    def _over_grpc(self, clip: AudioClip, target: GrpcTarget, timeout: float) -> str:
        request = speech_pb2.TranscribeRequest(audio=clip.to_proto(),
                                               language=self.call.language)
        return str(target.invoke("Transcribe", request, timeout).text)

    def _over_openai(self, clip: AudioClip, target: OpenAITarget, timeout: float) -> str:
        samples = np.frombuffer(clip.pcm, "<i2").reshape(-1, clip.channels)
        return transcription(target, encode_wav(samples, clip.sample_rate),
                             self.call.language, timeout)


METHOD = Method("Transcribe", TranscribeCall, "oricf.v1.SpeechRecognizer",
                speech_pb2_grpc.SpeechRecognizerStub, ServingHealth("oricf.v1.SpeechRecognizer"),
                Transcribe, protocols=frozenset({"grpc", "openai"}), hears=True, rank=1)
