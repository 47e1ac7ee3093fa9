"""What the gateway's shells (oricf.gateway.ros.spin, oricf.gateway.without_ros and the
hosted pipeline of `oricf mcp --config`, oricf.gateway.hosted) start beside a running
pipeline: the operations on it (oricf.gateway.operations.view) with the agent's actuation
(oricf.gateway.actuation) when its YAML has `agent:` targets, and the control API
(oricf.gateway.control.server) when it has `control:`. The shells import this module, not
a surface's package, and the surfaces import the core, never each other.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from oricf.gateway.actuation.actuation import Actuation
from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.actuation.policy import AgentPolicy
from oricf.gateway.actuation.senders import Sender, Senders
from oricf.gateway.operations.view import PipelineView
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.text_channels import Channels

log = logging.getLogger(__name__)


def ros_sender(policy: AgentPolicy) -> Sender:
    """The agent's publisher of topic targets (rclpy imported only now)."""
    from oricf.gateway.ros.commands import RosSender

    return RosSender(policy)


def make_view(pipeline: Pipeline, channels: Channels, audit: AuditLog | None = None
              ) -> PipelineView:
    """The control view of a started pipeline, with actuation if it has an agent policy."""
    config = pipeline.config
    if audit is None:
        audit = AuditLog(config.agent.audit if config.agent else None)
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
    from oricf.gateway.control.server import ControlServer  # starlette and uvicorn

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


def serve_gateway_control(pipeline: Pipeline, channels: Channels) -> Callable[[], None]:
    """For `oricf gateway`: the control API and the agent's actuation, when the pipeline's
    YAML asks for them; returns the stop."""
    if pipeline.config.control is None:
        return lambda: None
    return serve_control(make_view(pipeline, channels))
