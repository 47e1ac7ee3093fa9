"""Route inputs that are not ROS topics, by the input's source key (gateway.config.SOURCE_KEYS):
`url` video (video.py), `audio` utterances (audio.py), `text` lines (text.py). Topic inputs
belong to the ROS node, or to a replayed recording (replay.py); `product` inputs to the
pipeline itself.
"""

from __future__ import annotations

import importlib
from typing import Any

from oricf.gateway.channels import Channels
from oricf.gateway.config import PipelineConfig
from oricf.gateway.sources.base import OnEnd, Source, Submit

# source key -> "module:class" (imported only when a route uses it: audio needs its extra)
SOURCES = {
    "url": "oricf.gateway.sources.video:VideoSource",
    "audio": "oricf.gateway.sources.audio:AudioSource",
    "text": "oricf.gateway.sources.text:TextSource",
}
# Sources that read the pipeline's text channels are given them.
USES_CHANNELS = {"text"}


def make_sources(config: PipelineConfig, submit: dict[str, Submit], on_end: OnEnd,
                 channels: Channels) -> list[Source]:
    """One source per route whose input has a source here; `submit[route]` feeds the route."""
    sources = []
    for name, route in config.routes.items():
        key = route.input.source
        if key not in SOURCES:
            continue
        module, _, cls = SOURCES[key].partition(":")
        factory = getattr(importlib.import_module(module), cls)
        extra: dict[str, Any] = {"channels": channels} if key in USES_CHANNELS else {}
        sources.append(factory(name, route.input, submit[name], on_end, **extra))
    return sources


__all__ = ["SOURCES", "OnEnd", "Source", "Submit", "make_sources"]
