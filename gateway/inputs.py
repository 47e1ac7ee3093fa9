"""A pipeline's inputs that run on threads of their own: one source per route whose input's
key has one (oricf.gateway.sources, found through components.SOURCES). Topic inputs belong to
the ROS node, or to a replayed recording (oricf.gateway.recording.replay); `product` inputs to
the pipeline itself.
"""

from __future__ import annotations

import functools

from oricf.gateway.channels.server import Channels
from oricf.gateway.components import SOURCES, ComponentContext, OnEnd, Source, Submit, TopicIo
from oricf.gateway.config import PipelineConfig
from oricf.gateway.control.loop import ControlLoop
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.speaking import Speaking


def make_sources(config: PipelineConfig, submit: dict[str, Submit], on_end: OnEnd,
                 channels: Channels, speaking: Speaking | None = None,
                 topics: TopicIo | None = None,
                 loops: dict[str, ControlLoop] | None = None) -> list[Source]:
    """One source per route whose input has a source here; `submit[route]` feeds the route;
    `topics`: the ROS node's, for sources that read and write topics themselves; `loops`
    gets the control loops by route."""
    context = ComponentContext(config, channels, speaking or Speaking(), topics=topics,
                               loops=loops if loops is not None else {})
    sources = []
    for name, route in config.routes.items():
        opener = SOURCES[route.input.source].open
        if opener is not None:
            sources.append(opener(name, route.input, submit[name], on_end, context))
    return sources


def pipeline_sources(pipeline: Pipeline, channels: Channels, on_end: OnEnd,
                     topics: TopicIo | None = None) -> list[Source]:
    """The pipeline's sources that are no ROS topics, each feeding its route."""
    submit: dict[str, Submit] = {name: functools.partial(pipeline.submit, name)
                                 for name in pipeline.config.routes}
    return make_sources(pipeline.config, submit, on_end, channels, pipeline.speaking, topics,
                        pipeline.loops)


__all__ = ["make_sources", "pipeline_sources"]
