"""Route values as Foxglove messages (foxglove.messages): a frame as a CompressedImage, its
detections as ImageAnnotations (a box and a label per detection, with the track id when a
tracker set one), numbers as JSON messages a Plot panel reads (`.value`), text as Log lines.
Pure functions: no server, no threads."""

from __future__ import annotations

import json
import math
import zlib
from collections.abc import Iterable, Mapping
from typing import Any

from foxglove import Schema
from foxglove.messages import (
    CircleAnnotation,
    Color,
    CompressedImage,
    ImageAnnotations,
    Log,
    LogLevel,
    Point2,
    PointsAnnotation,
    PointsAnnotationType,
    TextAnnotation,
    Timestamp,
)

from oricf.gateway.values import Frame
from oricf.imaging import ENCODED, Detection, encode_image

# Box colours, one per label (chosen by the label's CRC, so a label keeps its colour).
PALETTE = ((0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16),
           (0.58, 0.4, 0.74), (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.74, 0.74, 0.13))
MAX_LOG_CHARS = 4000
INVISIBLE = Color(r=0.0, g=0.0, b=0.0, a=0.0)


def timestamp(ns: int) -> Timestamp:
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def compressed_image(frame: Frame, route: str, ns: int, jpeg_quality: int) -> CompressedImage:
    """JPEG and PNG frames go as they came; raw pixels are encoded as JPEG here."""
    if frame.encoding in ENCODED:
        data, format_ = frame.data, frame.encoding
    else:
        data, format_ = encode_image(frame.pixels(), "jpeg", jpeg_quality), "jpeg"
    return CompressedImage(timestamp=timestamp(ns), frame_id=route, data=data, format=format_)


def label_color(label: str, alpha: float = 1.0) -> Color:
    r, g, b = PALETTE[zlib.crc32(label.encode()) % len(PALETTE)]
    return Color(r=r, g=g, b=b, a=alpha)


def caption(detection: Detection) -> str:
    track = f" #{detection.track_id}" if detection.track_id is not None else ""
    return f"{detection.label}{track} {detection.score:.2f}"


def image_annotations(detections: Iterable[Detection], ns: int) -> ImageAnnotations:
    """Each detection as a closed outline of its box (pixels of the frame) and its caption.
    A frame without detections gets one invisible circle instead: the message has no time of
    its own, only its annotations do, and a viewer that matches annotations to images by
    time (Lichtblick's Image panel with sync on) would otherwise wait for them and not show
    the frame."""
    stamp = timestamp(ns)
    boxes, texts = [], []
    for d in detections:
        box = d.box
        corners = [Point2(x=box.x_min, y=box.y_min), Point2(x=box.x_max, y=box.y_min),
                   Point2(x=box.x_max, y=box.y_max), Point2(x=box.x_min, y=box.y_max)]
        boxes.append(PointsAnnotation(timestamp=stamp, type=PointsAnnotationType.LineLoop,
                                      points=corners, outline_color=label_color(d.label),
                                      thickness=2.0))
        texts.append(TextAnnotation(timestamp=stamp, position=Point2(x=box.x_min, y=box.y_min),
                                    text=caption(d), font_size=14.0,
                                    text_color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
                                    background_color=label_color(d.label, 0.7)))
    if not boxes:
        return ImageAnnotations(circles=[CircleAnnotation(
            timestamp=stamp, position=Point2(x=0, y=0), diameter=0.0, thickness=0.0,
            fill_color=INVISIBLE, outline_color=INVISIBLE)])
    return ImageAnnotations(points=boxes, texts=texts)


def is_number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def plottable(value: Any) -> dict[str, float] | None:
    """A number as {"value": x}; a mapping's numeric entries as they are (e.g. counts per
    label, crossings in and out); None for anything else."""
    if is_number(value):
        return {"value": float(value)}
    if isinstance(value, Mapping):
        numbers = {str(k): float(v) for k, v in value.items() if is_number(v)}
        return numbers or None
    return None


def log_line(text: str, name: str, ns: int) -> Log:
    return Log(timestamp=timestamp(ns), level=LogLevel.Info, message=text[:MAX_LOG_CHARS],
               name=name)


def json_channel_schema(topic: str, first: Mapping[str, Any]) -> Schema:
    """A JSON channel's schema, named after its topic (`/people/count`: oricf.people.count):
    viewers show the name beside each message (the SDK would name it `schema-` and random
    letters)."""
    name = "oricf" + ".".join(topic.split("/"))
    return Schema(name=name, encoding="jsonschema",
                  data=json.dumps(json_schema(first)).encode())


def json_schema(message: Mapping[str, Any]) -> dict[str, Any]:
    """The JSON schema of a flat message, from its first value (its channel's schema)."""
    kinds = {bool: "boolean", int: "number", float: "number", str: "string"}
    return {"type": "object",
            "properties": {k: {"type": kinds.get(type(v), "string")} for k, v in
                           message.items()}}
