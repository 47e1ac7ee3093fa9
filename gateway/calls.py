"""Turns a route's record into a request for its method, and the response into fields.

    Detect      image            -> detections, counts, annotated
    Transcribe  audio            -> transcript, duration_s (an empty transcript ends the route)
    Generate    prompt template  -> answer (context: data products as typed facts, stale ones
                                    never as current)
    Infer       image            -> detection model: detections, counts
                                    classification model: classes, label, score

Each method's binder runs once per route (e.g. building a declared model's head) and
returns the function that handles one record.
"""

from __future__ import annotations

import json
import logging
import numbers
from collections import Counter
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

from oricf.errors import InvalidInput
from oricf.gateway.values import AudioClip, Frame, Record
from oricf.imaging import Box, Detection, encoded_size
from oricf.models.heads import (
    ClassificationHead,
    DetectionHead,
    Prepared,
    declared_head,
)
from oricf.models.image import geometry
from oricf.models.wire import infer_request, response_outputs
from oricf.v1 import common_pb2, detector_pb2, language_pb2, speech_pb2

if TYPE_CHECKING:
    from oricf.gateway.config import (
        DetectCall,
        EndpointConfig,
        GenerateCall,
        InferCall,
        TranscribeCall,
    )
    from oricf.gateway.endpoints import Endpoint
    from oricf.gateway.products import ProductStore, Reading

log = logging.getLogger(__name__)

Invoke: TypeAlias = Callable[[Record], Record]
Binder: TypeAlias = Callable[[Any, "Endpoint", "ProductStore"], Invoke]


class Skip(Exception):
    """Nothing to pass on for this message (e.g. silence transcribed to nothing)."""


def _frame(record: Record, method: str) -> Frame:
    frame = record.get("image")
    if not isinstance(frame, Frame):
        raise InvalidInput(f"{method} needs an image input")
    return frame


def detect_request(record: Record, call: DetectCall, endpoint: EndpointConfig
                   ) -> detector_pb2.DetectRequest:
    frame = _frame(record, "Detect")
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


def detect(call: DetectCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    return lambda record: detect_fields(
        endpoint.call("Detect", detect_request(record, call, endpoint.config)))


def transcribe_request(record: Record, call: TranscribeCall) -> speech_pb2.TranscribeRequest:
    clip = record.get("audio")
    if not isinstance(clip, AudioClip):
        raise InvalidInput("Transcribe needs an audio input")
    return speech_pb2.TranscribeRequest(audio=clip.to_proto(), language=call.language)


def transcribe_fields(response: speech_pb2.Transcript) -> Record:
    text = response.text.strip()
    if not text:
        raise Skip("the audio transcribed to no words")
    return {"transcript": text, "duration_s": response.duration_s}


def transcribe(call: TranscribeCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    return lambda record: transcribe_fields(
        endpoint.call("Transcribe", transcribe_request(record, call)))


def generate_request(record: Record, call: GenerateCall, products: ProductStore
                     ) -> language_pb2.GenerateRequest:
    try:
        prompt = call.prompt.format_map(record).strip()
    except (KeyError, IndexError, ValueError) as exc:
        raise InvalidInput(f"prompt template {call.prompt!r}: cannot fill {exc}") from None
    if not prompt:
        raise Skip("empty prompt")
    readings = products.context(call.context.products, call.context.stale) if call.context \
        else []
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


def generate(call: GenerateCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    def invoke(record: Record) -> Record:
        request = generate_request(record, call, products)
        if log.isEnabledFor(logging.DEBUG):
            log.debug("Generate prompt %r facts %s", request.prompt, facts_text(request.facts))
        return {"answer": endpoint.call("Generate", request).text.strip()}

    return invoke


def infer_fields(call: InferCall) -> tuple[str, ...]:
    task = call.declaration.task
    return ("detections", "counts") if task is None or task.kind == "detection" \
        else ("classes", "label", "score")


def _encoded_input(frame: Frame, head: DetectionHead | ClassificationHead, quality: int
                   ) -> Prepared:
    """The frame as one JPEG (or its own encoding) for the server to pre-process."""
    image = frame.to_proto("jpeg", quality)
    size = (image.width, image.height) if image.width else encoded_size(image.data)[1:]
    tensor = np.empty(1, dtype=object)
    tensor[0] = image.data
    return Prepared({head.input_name: tensor},
                    geometry(size[0], size[1], head.image, head.size), 0.0)


def infer(call: InferCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    head = declared_head(call.declaration)
    wanted = [head.output] if head.output else []
    label_ids = {label: i for i, label in enumerate(head.labels)}
    class_ids = (np.array(sorted(label_ids[label] for label in call.labels), np.int64)
                 if call.labels else None)
    transport = endpoint.config.image

    def invoke(record: Record) -> Record:
        frame = _frame(record, "Infer")
        prepared = (_encoded_input(frame, head, transport.jpeg_quality)
                    if transport.transport == "jpeg" else head.prepare(frame.pixels()))
        request = infer_request(call.server_model, prepared.feeds, wanted)
        outputs = response_outputs(endpoint.call("ModelInfer", request))
        if isinstance(head, ClassificationHead):
            classes = head.decode(outputs, prepared, call.top_k)
            return {"classes": list(zip(classes.labels, classes.scores, strict=True)),
                    "label": classes.labels[0], "score": classes.scores[0]}
        found = head.decode(outputs, prepared, call.min_score or head.task.min_score,
                            class_ids)
        detections = [Detection(head.labels[c], int(c), float(s), Box(*map(float, b)))
                      for b, s, c in zip(found.boxes, found.scores, found.class_ids,
                                         strict=True)]
        counts = dict.fromkeys(call.labels, 0)
        counts.update(Counter(d.label for d in detections))
        return {"detections": detections, "counts": counts}

    return invoke
