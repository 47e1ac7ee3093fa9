"""Speech recognition over OpenAI's audio API: POST /v1/audio/transcriptions (a multipart
upload) and GET /v1/models, on the model the gRPC side serves.

The file is decoded with the service's limits (upload.py), then recognised as a Transcribe
request is. `response_format` json and text give the whole file's transcript; verbose_json
cuts the audio into utterances with the service's voice-activity endpointing (as
TranscribeStream does) and gives each as a segment with its start and end time.
"""

from __future__ import annotations

from typing import Any

from starlette.datastructures import UploadFile
from starlette.requests import Request
from starlette.responses import JSONResponse, PlainTextResponse, Response
from starlette.routing import Route

from oricf.services.asr.config import AsrConfig
from oricf.services.asr.limits import AudioLimits
from oricf.services.asr.model import SpeechModel
from oricf.services.asr.upload import decode_upload
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.http.app import check_model, models_route
from oricf.services.runtime.http.calls import run_blocking
from oricf.services.runtime.http.errors import InvalidParam

FORMATS = ("json", "text", "verbose_json")
MAX_FIELD_BYTES = 64 * 1024  # a form field other than the file (language, prompt...)


def _field(form: Any, name: str) -> str | None:
    value = form.get(name)
    if value is None:
        return None
    if not isinstance(value, str):
        raise InvalidParam(f"{name}: must be a text field, not a file", param=name)
    return value.strip()


def _options(form: Any) -> tuple[str, str]:
    """(response_format, language) of the form, refusing what this service cannot do."""
    response_format = _field(form, "response_format") or "json"
    if response_format not in FORMATS:
        raise InvalidParam(f"response_format: '{response_format[:40]}' is not one of "
                           f"{', '.join(FORMATS)}", param="response_format")
    if _field(form, "prompt"):
        raise InvalidParam("prompt: not supported by this service (its words to bias "
                           "towards are model.options.initial_prompt in its YAML)",
                           param="prompt")
    temperature = _field(form, "temperature")
    if temperature and temperature not in ("0", "0.0"):
        raise InvalidParam("temperature: this service decodes at the temperature of its "
                           "YAML; send 0 or leave it out", param="temperature")
    granularities = form.getlist("timestamp_granularities[]")
    if any(g != "segment" for g in granularities):
        raise InvalidParam("timestamp_granularities[]: only 'segment' is available",
                           param="timestamp_granularities[]")
    return response_format, _field(form, "language") or ""


def _segments(model: SpeechModel, samples: Any, language: str,
              still_wanted: Any) -> list[dict[str, Any]]:
    endpointer = model.endpointer()
    utterances = endpointer.push(samples, still_wanted) + endpointer.flush()
    rate = model.sample_rate
    segments = []
    for i, utterance in enumerate(utterances):
        still_wanted()
        text = model.infer(utterance.samples, language).text
        segments.append({"id": i, "seek": utterance.start, "start": utterance.start / rate,
                         "end": utterance.end / rate, "text": text, "tokens": []})
    return segments


class Transcriptions:
    def __init__(self, slot: ModelSlot[SpeechModel], config: AsrConfig) -> None:
        self.slot = slot
        self.config = config
        self.limits = AudioLimits(config.audio)
        self.name = config.model.name

    def routes(self) -> list[Route]:
        return [Route("/v1/audio/transcriptions", self.transcribe, methods=["POST"]),
                models_route(self.name)]

    async def transcribe(self, request: Request) -> Response:
        if not (request.headers.get("content-type") or "").startswith("multipart/form-data"):
            raise InvalidParam("send the audio as multipart/form-data with a `file` field",
                               param="file")
        async with request.form(max_files=1, max_fields=16,
                                max_part_size=MAX_FIELD_BYTES) as form:
            upload = form.get("file")
            if not isinstance(upload, UploadFile):
                raise InvalidParam("file: an audio file is needed", param="file")
            check_model(_field(form, "model"), self.name)
            response_format, language = _options(form)
            data = await upload.read()
        model = self.slot.get()

        def work(still_wanted: Any) -> dict[str, Any]:
            return self._recognise(model, data, language, response_format, still_wanted)

        result = await run_blocking(request, work)
        if response_format == "text":
            return PlainTextResponse(result["text"])
        return JSONResponse(result)

    def _recognise(self, model: SpeechModel, data: bytes, language: str,
                   response_format: str, still_wanted: Any) -> dict[str, Any]:
        audio = decode_upload(data, self.limits, model.sample_rate)
        samples = audio.samples
        still_wanted()
        if response_format != "verbose_json":
            return {"text": model.infer(samples, language).text}
        segments = _segments(model, samples, language, still_wanted)
        return {"task": "transcribe", "language": language or model.default_language,
                "duration": audio.duration_s,
                "text": " ".join(s["text"] for s in segments if s["text"]),
                "segments": segments}


def routes(slot: ModelSlot[SpeechModel], config: AsrConfig) -> list[Route]:
    return Transcriptions(slot, config).routes()
