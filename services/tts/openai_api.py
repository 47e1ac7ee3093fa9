"""Speech synthesis over OpenAI's audio API: POST /v1/audio/speech and GET /v1/models.

The JSON body becomes the same checked job as a gRPC Synthesize (model.prepare), so a bad
`input` or `voice` is a 400 in OpenAI's error shape before any audio is made. The audio is
sent as it is made, sentence by sentence: `pcm` as raw 16-bit little-endian mono samples at
the voice's rate (the `x-sample-rate` header says which; OpenAI's own is 24 kHz), `wav` as
one WAV file whose header carries the streamed-length placeholder (as `espeak-ng --stdout`
writes), since its length is not known when the first sentence goes out.
"""

from __future__ import annotations

import logging
import math
from collections.abc import AsyncGenerator, AsyncIterator
from typing import Any

from starlette.requests import Request
from starlette.responses import Response, StreamingResponse
from starlette.routing import Route
from starlette.types import Receive

from oricf.audio import STREAMED_DATA_SIZE, wav_header
from oricf.errors import Cancelled, InvalidInput
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.http.app import check_model, models_route
from oricf.services.runtime.http.calls import Presence, iterate_blocking, read_json
from oricf.services.runtime.http.errors import InvalidParam
from oricf.services.tts.config import TtsConfig
from oricf.services.tts.model import Job, SpokenSentence, SynthesisModel

log = logging.getLogger(__name__)

FORMATS = {"wav": "audio/wav", "pcm": "audio/pcm"}
PARAMS = {"text": "input", "voice": "voice", "speed": "speed"}  # the model's names -> the API's
KNOWN_FIELDS = {"model", "input", "voice", "response_format", "speed", "instructions",
                "stream_format"}


def _text(body: dict[str, Any], name: str, default: str = "") -> str:
    value = body.get(name, default)
    if value is None:
        return default
    if not isinstance(value, str):
        raise InvalidParam(f"{name}: must be a string", param=name)
    return value


def _speed(body: dict[str, Any]) -> float:
    value = body.get("speed", 1.0)
    if value is None:
        return 1.0
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value == 0:  # 0 is "unset" only over gRPC
        raise InvalidParam("speed: must be a number from 0.25 to 4.0", param="speed")
    return float(value)


def _options(body: dict[str, Any]) -> str:
    """The response format, refusing what this service does not do."""
    unknown = sorted(set(body) - KNOWN_FIELDS)
    if unknown:
        raise InvalidParam(f"{unknown[0][:40]}: not a field of this API", param=unknown[0][:40])
    response_format = _text(body, "response_format", "wav")
    if response_format not in FORMATS:
        raise InvalidParam(f"response_format: '{response_format[:40]}' is not available here; "
                           f"use {' or '.join(FORMATS)}", param="response_format")
    if _text(body, "instructions"):
        raise InvalidParam("instructions: these voices take no instructions",
                           param="instructions")
    if _text(body, "stream_format", "audio") != "audio":
        raise InvalidParam("stream_format: only 'audio' is available", param="stream_format")
    return response_format


def _in_api_terms(exc: InvalidInput) -> InvalidInput:
    """A refusal naming the field as this API calls it (input, not text)."""
    field, _, rest = str(exc).partition(": ")
    param = PARAMS.get(field)
    return exc if param is None else InvalidParam(f"{param}: {rest}", param=param)


def _prepare(model: SynthesisModel, body: dict[str, Any]) -> Job:
    """The checked job."""
    try:
        return model.prepare(_text(body, "input"), _text(body, "voice"), _speed(body))
    except InvalidInput as exc:
        raise _in_api_terms(exc) from None


class Speech:
    def __init__(self, slot: ModelSlot[SynthesisModel], config: TtsConfig) -> None:
        self.slot = slot
        self.name = config.name

    def routes(self) -> list[Route]:
        return [Route("/v1/audio/speech", self.speech, methods=["POST"]),
                models_route(self.name)]

    async def speech(self, request: Request) -> Response:
        body = await read_json(request)
        check_model(_text(body, "model"), self.name)
        response_format = _options(body)
        model = self.slot.get()
        job = _prepare(model, body)
        presence = Presence()
        sentences = iterate_blocking(model.speak(job, presence.still_wanted), presence)
        try:
            # The first sentence is made before the answer starts, so a failure is still
            # an HTTP status rather than a cut stream.
            first = await anext(sentences)
        except InvalidInput as exc:
            await sentences.aclose()
            raise _in_api_terms(exc) from None
        except BaseException:
            await sentences.aclose()
            raise
        rate = job.voice.sample_rate
        head = wav_header(rate, 1, STREAMED_DATA_SIZE) if response_format == "wav" else b""
        return SpeechStream(_audio(head, first, sentences), presence,
                            media_type=FORMATS[response_format],
                            headers={"x-sample-rate": str(rate)})


class SpeechStream(StreamingResponse):
    """The audio as it is made; a client that disconnects stops the synthesis at once.

    The worker thread making a piece is not interrupted by the stream's cancellation, so the
    disconnect is passed on as it arrives: the voice's next check between pieces stops."""

    def __init__(self, content: AsyncIterator[bytes], presence: Presence,
                 **options: Any) -> None:
        super().__init__(content, **options)
        self.presence = presence

    async def listen_for_disconnect(self, receive: Receive) -> None:
        try:
            await super().listen_for_disconnect(receive)
        finally:
            self.presence.leave()


async def _audio(head: bytes, first: SpokenSentence,
                 rest: AsyncGenerator[SpokenSentence, None]) -> AsyncIterator[bytes]:
    try:
        yield head + first.samples.astype("<i2").tobytes()
        async for sentence in rest:
            yield sentence.samples.astype("<i2").tobytes()
    except Cancelled:
        log.debug("speech stream stopped: the client went away")
    except InvalidInput as exc:
        # The answer has started: its status cannot change any more, so the audio ends here.
        log.warning("speech stream cut: %s", exc)
    finally:
        await rest.aclose()


def routes(slot: ModelSlot[SynthesisModel], config: TtsConfig) -> list[Route]:
    return Speech(slot, config).routes()
