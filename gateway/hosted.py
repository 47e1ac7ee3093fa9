"""A pipeline run inside another program (`oricf mcp --config`), started as `oricf gateway`
would start it: with a ROS node on an executor thread of its own when the pipeline has
topics, else its sources, routes and outlets alone. Also makes the pipeline's agent
actuation and control view, and serves its control API if the YAML has `control:`
(oricf.gateway.surfaces). The third shell beside oricf.gateway.ros.spin and
oricf.gateway.without_ros.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

from oricf.gateway.actuation.audit import AuditLog
from oricf.gateway.config import PipelineConfig
from oricf.gateway.inputs import pipeline_sources
from oricf.gateway.operations.view import PipelineView
from oricf.gateway.outlets import Outlets
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.surfaces import make_view, serve_control
from oricf.gateway.text_channels import Channels

log = logging.getLogger(__name__)


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
