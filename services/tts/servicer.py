"""oricf.v1.SpeechSynthesizer: turns requests into a checked job, speaks it, and back."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator

import grpc
import numpy as np

from oricf.audio import ENCODINGS, encode_wav
from oricf.errors import InvalidInput
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.errors import check_wanted
from oricf.services.runtime.info import model_info_response
from oricf.services.tts.model import SpokenSentence, SynthesisModel
from oricf.v1 import common_pb2, speech_pb2, synthesis_pb2, synthesis_pb2_grpc

log = logging.getLogger(__name__)


def check_encoding(encoding: str) -> str:
    encoding = encoding.lower() or ENCODINGS[0]
    if encoding not in ENCODINGS:
        raise InvalidInput(f"encoding: '{encoding[:40]}' is not one of {', '.join(ENCODINGS)}")
    return encoding


def audio_message(samples: np.ndarray, rate: int, encoding: str) -> speech_pb2.Audio:
    data = encode_wav(samples, rate) if encoding == "wav" else samples.astype("<i2").tobytes()
    return speech_pb2.Audio(data=data, encoding=encoding, sample_rate=rate, channels=1)


def _still_wanted(context: grpc.ServicerContext) -> Callable[[], None]:
    """Checked between the pieces a voice makes: a call whose deadline passed or whose
    caller went away (a cancelled stream) stops there."""
    return lambda: check_wanted(context, "during synthesis")


class SpeechSynthesizerServicer(synthesis_pb2_grpc.SpeechSynthesizerServicer):
    def __init__(self, slot: ModelSlot[SynthesisModel]) -> None:
        self.slot = slot

    def Synthesize(self, request: synthesis_pb2.SynthesizeRequest,
                   context: grpc.ServicerContext) -> synthesis_pb2.SynthesizedAudio:
        started = time.perf_counter()
        model = self.slot.get()
        encoding = check_encoding(request.encoding)
        job = model.prepare(request.text, request.voice, request.speed)
        parts: list[SpokenSentence] = list(model.speak(job, _still_wanted(context)))
        samples = np.concatenate([p.samples for p in parts])
        rate = job.voice.sample_rate
        reply = synthesis_pb2.SynthesizedAudio(
            audio=audio_message(samples, rate, encoding), duration_s=len(samples) / rate,
            text=" ".join(p.text for p in parts), last=True, voice=job.voice.name,
            timings=common_pb2.Timings(inference_ms=sum(p.inference_ms for p in parts),
                                       total_ms=(time.perf_counter() - started) * 1e3))
        log.debug("synthesized %d sentence(s), %.2f s of audio, in %.0f ms", len(parts),
                  reply.duration_s, reply.timings.total_ms)
        return reply

    def SynthesizeStream(self, request: synthesis_pb2.SynthesizeRequest,
                         context: grpc.ServicerContext
                         ) -> Iterator[synthesis_pb2.SynthesizedAudio]:
        """One message per sentence; total_ms of each counts from the request, so the first
        message's is the time to first audio."""
        started = time.perf_counter()
        model = self.slot.get()
        encoding = check_encoding(request.encoding)
        job = model.prepare(request.text, request.voice, request.speed)
        for sentence in model.speak(job, _still_wanted(context)):
            yield synthesis_pb2.SynthesizedAudio(
                audio=audio_message(sentence.samples, sentence.sample_rate, encoding),
                duration_s=sentence.duration_s, sentence=sentence.index, text=sentence.text,
                last=sentence.last, voice=job.voice.name,
                timings=common_pb2.Timings(inference_ms=sentence.inference_ms,
                                           total_ms=(time.perf_counter() - started) * 1e3))

    def GetModelInfo(self, request: common_pb2.GetModelInfoRequest,
                     context: grpc.ServicerContext) -> common_pb2.GetModelInfoResponse:
        return model_info_response("tts", self.slot)
