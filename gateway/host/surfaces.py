"""What starts beside a running pipeline (oricf.gateway.host.gateway.Gateway.activate): the
live view (oricf.gateway.live_view) when its YAML has `foxglove:`, the operations on it
(oricf.gateway.operations.view) with the agent's actuation (oricf.gateway.actuation) when
it has `agent:` targets, and the control API (oricf.gateway.api.server) when it has
`control:`. The host imports the surfaces; the surfaces import the core, never each other.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from oricf.gateway.actuation.actuation import Actuation
from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.actuation.senders import MakeSender, Senders
from oricf.gateway.channels.server import Channels
from oricf.gateway.listeners import LiveViewConfig
from oricf.gateway.operations.view import PipelineView
from oricf.gateway.pipeline import Pipeline

if TYPE_CHECKING:
    from oricf.gateway.live_view.view import LiveView

log = logging.getLogger(__name__)


def start_live_view(pipeline: Pipeline, config: LiveViewConfig) -> LiveView:
    """The live view of a started pipeline: every route's records and data products shown,
    its own state plotted once a second."""
    from oricf.gateway.live_view.states import states
    from oricf.gateway.live_view.topics import declared_topics
    from oricf.gateway.live_view.view import LiveView  # foxglove-sdk, only when used

    view = LiveView(config, pipeline.config.node_name)
    for topic, kind in declared_topics(pipeline.config):
        view.declare(topic, kind)
    view.start(lambda: states(pipeline))
    for route in pipeline.routes.values():
        route.watchers.append(view)
    for product in pipeline.products.declared():
        pipeline.products.subscribe(product, functools.partial(view.show_product, product))
    return view


def make_view(pipeline: Pipeline, channels: Channels, audit: AuditLog,
              ros_sender: MakeSender | None = None) -> PipelineView:
    """The operations on a started pipeline, with actuation if it has an agent policy
    (`ros_sender` publishes its topic targets)."""
    config = pipeline.config
    actuation = (Actuation(config.agent, Senders(config.agent, channels, ros_sender), audit,
                           channels)
                 if config.agent and config.agent.targets else None)
    return PipelineView(pipeline, actuation, audit)


def serve_control(view: PipelineView) -> Callable[[], None]:
    """The control API of the view's pipeline if its YAML has `control:`; returns the stop
    (which also closes the view: the deadman's zero commands go out first)."""
    config = view.pipeline.config.control
    if config is None:
        return view.close
    from oricf.gateway.api.server import ControlServer  # starlette and uvicorn

    server = ControlServer(config, view)
    try:
        server.start()
    except BaseException:
        view.close()
        raise

    def stop() -> None:
        server.close()
        view.close()

    return stop
