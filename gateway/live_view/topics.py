"""The live view's topics that are known when the pipeline loads, so their channels are
advertised from the start: a viewer can subscribe before the first value, which a channel
made on its first value would never carry to anyone (an answer is rare; a count is not).
Numbers are still advertised on their first value: the next one follows within a frame."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Literal, get_type_hints

from oricf.gateway.components import METHODS
from oricf.gateway.config import PipelineConfig

Kind = Literal["image", "detections", "log"]


def declared_topics(config: PipelineConfig) -> Iterator[tuple[str, Kind]]:
    """(topic, kind): each camera route's image and detections, and every text field (a
    text input, a transcript, an answer)."""
    for name, route in config.routes.items():
        if route.input.field == "image":
            yield f"/{name}/image", "image"
        elif route.input.field == "text":
            yield f"/{name}/text", "log"
        result = METHODS[route.call.method].result(route.call)
        for field, hint in get_type_hints(result).items():
            if field == "detections":
                yield f"/{name}/detections", "detections"
            elif hint is str:
                yield f"/{name}/{field}", "log"
