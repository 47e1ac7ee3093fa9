"""A pipeline run in this process (`oricf mcp --config`), started as `oricf gateway` would
start it: with a ROS node on an executor thread of its own when the pipeline has topics,
else its sources, routes and outlets alone. Also makes the pipeline's agent actuation and
control view, and serves its control API if the YAML has `control:`.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from oricf.gateway.agents.actuation import Actuation
from oricf.gateway.agents.audit import AuditLog
from oricf.gateway.agents.senders import Senders
from oricf.gateway.config import PipelineConfig
from oricf.gateway.control.view import PipelineView
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.sinks import Outlets
from oricf.gateway.sources import pipeline_sources
from oricf.gateway.text_channels import Channels

log = logging.getLogger(__name__)


def make_view(pipeline: Pipeline, channels: Channels, audit: AuditLog | None = None
              ) -> PipelineView:
    """The control view of a started pipeline, with actuation if it has an agent policy."""
    config = pipeline.config
    if audit is None:
        audit = AuditLog(config.agent.audit if config.agent else None)
    actuation = (Actuation(config.agent, Senders(config.agent, channels), audit, channels)
                 if config.agent and config.agent.targets else None)
    return PipelineView(pipeline, actuation, audit)


def serve_control(view: PipelineView) -> Callable[[], None]:
    """The control API of the view's pipeline if its YAML has `control:`; returns the stop
    (which also closes the view: the deadman's zero commands go out first)."""
    config = view.pipeline.config.control
    if config is None:
        return view.close
    from oricf.gateway.control.server import ControlServer

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


class HostedPipeline:
    """start() -> the view; stop() stops everything it started, the deadman's zero first."""

    def __init__(self, config: PipelineConfig, audit_path: Path | None = None) -> None:
        self.config = config
        self.audit_path = audit_path or (config.agent.audit if config.agent else None)
        self.view: PipelineView | None = None
        self._stops: list[Any] = []

    def start(self) -> PipelineView:
        if self.config.uses_ros:
            pipeline, channels = self._start_ros()
        else:
            pipeline, channels = self._start_plain()
        self.view = make_view(pipeline, channels, AuditLog(self.audit_path))
        self._stops.insert(0, serve_control(self.view))
        return self.view

    def _start_plain(self) -> tuple[Pipeline, Channels]:
        outlets = Outlets(self.config)
        pipeline = Pipeline(self.config, outlets)
        sources = pipeline_sources(pipeline, outlets.channels, lambda route: None)
        outlets.start()
        pipeline.start()
        for source in sources:
            source.start()

        def stop() -> None:
            for source in sources:
                source.stop()
            pipeline.stop()
            outlets.close()

        self._stops.append(stop)
        return pipeline, outlets.channels

    def _start_ros(self) -> tuple[Pipeline, Channels]:
        import rclpy
        from rclpy.context import Context

        from oricf.gateway.ros.dds import use_dds_profile
        from oricf.gateway.ros.executor import make_executor
        from oricf.gateway.ros.node import GatewayNode

        use_dds_profile()
        context = Context()
        rclpy.init(context=context)
        node = GatewayNode(self.config, context=context)
        executor = make_executor(self.config.executor_threads, context)
        executor.add_node(node)
        thread = threading.Thread(target=self._spin, args=(executor, context), daemon=True,
                                  name="gateway-ros")
        thread.start()

        def stop() -> None:
            node.shutdown()
            rclpy.try_shutdown(context=context)
            thread.join(5)
            executor.shutdown()
            node.destroy_node()

        self._stops.append(stop)
        return node.pipeline, node.outlets.channels

    @staticmethod
    def _spin(executor: Any, context: Any) -> None:
        from oricf.gateway.ros.executor import spin_until_shutdown

        try:
            spin_until_shutdown(executor, context.ok)
        except Exception as exc:  # the tools keep answering; the log says why ROS stopped
            log.error("gateway executor stopped: %s", exc)

    def stop(self) -> None:
        for stop in self._stops:
            try:
                stop()
            except Exception:
                log.exception("stopping the hosted pipeline")
        self._stops.clear()
