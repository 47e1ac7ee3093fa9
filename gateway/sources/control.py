"""control: a route that ticks at the policy's rate instead of once per message
(`input: {control: ...}`): the control loop of oricf.gateway.control on the ROS node's
topics. Its settings are oricf.gateway.control.settings; docs/control.md.
"""

from __future__ import annotations

from typing import Any

from oricf.config import Schema
from oricf.errors import ConfigError
from oricf.gateway.components import ComponentContext, OnEnd, Source, SourceKind, Submit
from oricf.gateway.control.settings import ControlSettings


class ControlInput(Schema):
    control: ControlSettings | None = None


def open_source(route: str, config: Any, submit: Submit, on_end: OnEnd,
                context: ComponentContext) -> Source:
    """The route's control loop, its state and cameras subscribed and its target's publisher
    made on the ROS node's topics."""
    from oricf.gateway.control.source import ControlSource  # the loop: when a pipeline runs

    settings: ControlSettings = config.control
    if context.topics is None:
        raise ConfigError(f"routes.{route}.input.control: reads and writes ROS topics: "
                          f"run the gateway with ROS")
    source = ControlSource(route, settings, submit, context.topics.publisher(
        settings.target.topic, settings.target.type))
    for topic, type_, take in source.takers():
        context.topics.subscribe(topic, type_, take)
    context.loops[route] = source.loop
    return source


COMPONENT = SourceKind("control", ControlInput, lambda config: "state", open_source,
                       latest=lambda config: True, ros=True, acts=True,
                       rate_hz=lambda config: config.control.rate_hz,
                       more_fields=lambda config: frozenset(
                           {"step", "capture_time_ns", "committed", "images"}), rank=6)
