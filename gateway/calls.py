"""Turns a route's record into a request for its method, and the response into fields.

    Detect      image            -> detections, counts, annotated
    Transcribe  audio            -> transcript, duration_s (an empty transcript ends the route)
    Generate    prompt template  -> answer (context: data products, stale ones never as current)
"""

from __future__ import annotations

import logging
from typing import Any

from oricf.errors import InvalidInput
from oricf.gateway.config import CallConfig, EndpointConfig
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.products import ProductStore
from oricf.gateway.values import AudioClip, Frame, Record
from oricf.imaging import Box, Detection
from oricf.v1 import detector_pb2, language_pb2, speech_pb2

log = logging.getLogger(__name__)


class Skip(Exception):
    """Nothing to pass on for this message (e.g. silence transcribed to nothing)."""


def detect_request(record: Record, call: CallConfig, endpoint: EndpointConfig
                   ) -> detector_pb2.DetectRequest:
    frame = record.get("image")
    if not isinstance(frame, Frame):
        raise InvalidInput("Detect needs an image input")
    return detector_pb2.DetectRequest(
        image=frame.to_proto(endpoint.image.transport, endpoint.image.jpeg_quality),
        labels=call.labels, min_score=call.min_score, annotate=call.annotate,
        annotate_encoding="bgr8" if call.annotate else "")


def detect_fields(response: detector_pb2.DetectResponse) -> Record:
    detections = [
        Detection(d.label, d.class_id, d.score,
                  Box(d.box.x_min, d.box.y_min, d.box.x_max, d.box.y_max))
        for d in response.detections]
    fields: Record = {"detections": detections, "counts": dict(response.counts)}
    if response.HasField("annotated") and response.annotated.data:
        a = response.annotated
        fields["annotated"] = Frame(a.data, a.encoding, a.width, a.height)
    return fields


def transcribe_request(record: Record, call: CallConfig) -> speech_pb2.TranscribeRequest:
    clip = record.get("audio")
    if not isinstance(clip, AudioClip):
        raise InvalidInput("Transcribe needs an audio input")
    return speech_pb2.TranscribeRequest(audio=clip.to_proto(), language=call.language)


def transcribe_fields(response: speech_pb2.Transcript) -> Record:
    text = response.text.strip()
    if not text:
        raise Skip("the audio transcribed to no words")
    return {"transcript": text, "duration_s": response.duration_s}


def generate_request(record: Record, call: CallConfig, products: ProductStore
                     ) -> language_pb2.GenerateRequest:
    try:
        prompt = call.prompt.format_map(record).strip()
    except (KeyError, IndexError, ValueError) as exc:
        raise InvalidInput(f"prompt template {call.prompt!r}: cannot fill {exc}") from None
    if not prompt:
        raise Skip("empty prompt")
    context = products.context(call.context.products, call.context.stale) if call.context else {}
    request = language_pb2.GenerateRequest(prompt=prompt, context=context,
                                           max_tokens=call.max_tokens, stop=call.stop)
    if call.temperature is not None:
        request.temperature = call.temperature
    return request


def generate_fields(response: language_pb2.GenerateResponse) -> Record:
    return {"answer": response.text.strip()}


def invoke(call: CallConfig, endpoint: Endpoint, products: ProductStore, record: Record
           ) -> Record:
    """One call of the route's method through its endpoint; returns the new fields."""
    response: Any
    if call.method == "Detect":
        response = endpoint.call("Detect", detect_request(record, call, endpoint.config))
        return detect_fields(response)
    if call.method == "Transcribe":
        response = endpoint.call("Transcribe", transcribe_request(record, call))
        return transcribe_fields(response)
    request = generate_request(record, call, products)
    log.debug("Generate prompt %r context %s", request.prompt, dict(request.context))
    return generate_fields(endpoint.call("Generate", request))
