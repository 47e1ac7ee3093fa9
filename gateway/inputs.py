"""A pipeline's inputs that are not ROS topics, by the input's source key: one source per
route (oricf.gateway.sources); topic inputs belong to the ROS node, or to a replayed recording
(oricf.gateway.recording.replay); `product` inputs to the pipeline itself.
"""

from __future__ import annotations

import functools
import importlib
from typing import Any

from oricf.gateway.config import PipelineConfig
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.sources.base import OnEnd, Source, Submit
from oricf.gateway.speaking import Speaking
from oricf.gateway.text_channels import Channels

# source key -> "module:class" (imported only when a route uses it: audio needs its extra)
SOURCES = {
    "url": "oricf.gateway.sources.video:VideoSource",
    "audio": "oricf.gateway.sources.audio:AudioSource",
    "text": "oricf.gateway.sources.text:TextSource",
}
# Sources that read the pipeline's text channels are given them; sources that hear the
# robot speak are given the pipeline's Speaking (oricf.gateway.speaking).
USES_CHANNELS = {"text"}
HEARS_SPEECH = {"audio"}


def make_sources(config: PipelineConfig, submit: dict[str, Submit], on_end: OnEnd,
                 channels: Channels, speaking: Speaking | None = None) -> list[Source]:
    """One source per route whose input has a source here; `submit[route]` feeds the route."""
    sources = []
    for name, route in config.routes.items():
        key = route.input.source
        if key not in SOURCES:
            continue
        module, _, cls = SOURCES[key].partition(":")
        factory = getattr(importlib.import_module(module), cls)
        extra: dict[str, Any] = {"channels": channels} if key in USES_CHANNELS else {}
        if key in HEARS_SPEECH and speaking is not None:
            extra["speaking"] = speaking
        sources.append(factory(name, route.input, submit[name], on_end, **extra))
    return sources


def pipeline_sources(pipeline: Pipeline, channels: Channels, on_end: OnEnd) -> list[Source]:
    """The pipeline's sources that are no ROS topics, each feeding its route."""
    submit: dict[str, Submit] = {name: functools.partial(pipeline.submit, name)
                                 for name in pipeline.config.routes}
    return make_sources(pipeline.config, submit, on_end, channels, pipeline.speaking)


__all__ = ["SOURCES", "make_sources", "pipeline_sources"]
