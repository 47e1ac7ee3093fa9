"""oricf.v1.SpeechRecognizer: turns requests into audio samples, calls the model, and back."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator

import grpc

from oricf.audio import decode_audio, to_model_input
from oricf.audio.endpointing import Utterance
from oricf.errors import InvalidInput
from oricf.services.asr.config import AsrConfig
from oricf.services.asr.limits import AudioLimits
from oricf.services.asr.model import SpeechModel
from oricf.services.asr.recognizer import Recognition
from oricf.services.asr.stream import StreamDecoder
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.errors import check_deadline, check_wanted
from oricf.services.runtime.info import model_info_response
from oricf.v1 import common_pb2, speech_pb2, speech_pb2_grpc

log = logging.getLogger(__name__)


class SpeechRecognizerServicer(speech_pb2_grpc.SpeechRecognizerServicer):
    def __init__(self, slot: ModelSlot[SpeechModel], config: AsrConfig) -> None:
        self.slot = slot
        self.config = config
        self.limits = AudioLimits(config.audio)

    def Transcribe(self, request: speech_pb2.TranscribeRequest,
                   context: grpc.ServicerContext) -> speech_pb2.Transcript:
        started = time.perf_counter()
        model = self.slot.get()
        audio = request.audio
        pcm = decode_audio(audio.data, audio.encoding, audio.sample_rate, audio.channels)
        self.limits.check(pcm.frames, pcm.channels, pcm.sample_rate)  # before any conversion
        samples = to_model_input(pcm, model.sample_rate)
        decode_ms = (time.perf_counter() - started) * 1e3
        # decoding may have used up the caller's time
        check_deadline(context, "while the audio was decoded, before recognition")
        result = model.infer(samples, request.language)
        transcript = _transcript(result, started)
        transcript.timings.decode_ms = decode_ms
        log.debug("transcribed %.2f s in %.0f ms: %r", result.duration_s,
                  transcript.timings.total_ms, result.text)
        return transcript

    def TranscribeStream(self, request_iterator: Iterator[speech_pb2.TranscribeStreamRequest],
                         context: grpc.ServicerContext) -> Iterator[speech_pb2.Transcript]:
        model = self.slot.get()
        decoder = StreamDecoder(model.sample_rate, self.config.audio.max_stream_s)
        endpointer = model.endpointer()
        count = 0

        def still_wanted() -> None:
            check_wanted(context, "during voice activity detection")

        for request in request_iterator:
            received = time.perf_counter()
            still_wanted()
            audio = request.audio
            samples = decoder.push(audio.data, audio.encoding, audio.sample_rate, audio.channels)
            for utterance in endpointer.push(samples, still_wanted):
                yield self._utterance(model, utterance, count, decoder, received, context)
                count += 1
        received = time.perf_counter()
        for utterance in endpointer.push(decoder.flush()) + endpointer.flush():
            yield self._utterance(model, utterance, count, decoder, received, context)
            count += 1
        if decoder.stray_bytes:
            raise InvalidInput(f"the stream ended inside a frame: {decoder.stray_bytes} stray "
                               f"byte(s) after the last whole frame were ignored")

    def GetModelInfo(self, request: common_pb2.GetModelInfoRequest,
                     context: grpc.ServicerContext) -> common_pb2.GetModelInfoResponse:
        return model_info_response("asr", self.slot)

    def _utterance(self, model: SpeechModel, utterance: Utterance, index: int,
                   decoder: StreamDecoder, received: float,
                   context: grpc.ServicerContext) -> speech_pb2.Transcript:
        """One streamed utterance's transcript.

        total_ms counts from the arrival of the chunk that completed the utterance: the
        delay a robot sees after the speaker's pause has been heard.
        """
        check_deadline(context, "before this utterance could be recognised")
        result = model.infer(utterance.samples)
        transcript = _transcript(result, received)
        transcript.utterance = index
        transcript.start_s = utterance.start / model.sample_rate
        transcript.end_s = utterance.end / model.sample_rate
        transcript.timings.decode_ms = decoder.take_decode_ms()
        transcript.timings.preprocess_ms = utterance.vad_ms
        log.debug("utterance %d (%.2f-%.2f s): %r", index, transcript.start_s,
                  transcript.end_s, result.text)
        return transcript


def _transcript(result: Recognition, started: float) -> speech_pb2.Transcript:
    return speech_pb2.Transcript(
        text=result.text, language=result.language, duration_s=result.duration_s,
        timings=common_pb2.Timings(
            inference_ms=result.timings_ms.get("inference_ms", 0.0),
            total_ms=(time.perf_counter() - started) * 1e3))
