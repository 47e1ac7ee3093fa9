"""A gateway run inside another program (`oricf mcp --config`), started as `oricf gateway`
would start it: with its ROS node spun on an executor thread of its own when the pipeline
has topics, else without ROS. Its operations (oricf.gateway.operations.view) are always
made, for the MCP server; the control API is served if the YAML has `control:`. The third
shell beside oricf.gateway.shells.ros and oricf.gateway.shells.without_ros.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from oricf.gateway.config import PipelineConfig
from oricf.gateway.host.gateway import Gateway
from oricf.gateway.operations.view import PipelineView
from oricf.gateway.ros.commands import RosSender

log = logging.getLogger(__name__)


class EmbeddedGateway:
    """start() -> the view; stop() stops everything it started, the deadman's zero first."""

    def __init__(self, config: PipelineConfig, audit_path: Path | None = None) -> None:
        self.config = config
        self.audit_path = audit_path
        self.view: PipelineView | None = None
        self._stop: Callable[[], None] | None = None

    def start(self) -> PipelineView:
        if self.config.uses_ros:
            gateway = self._start_ros()
        else:
            gateway = Gateway(self.config, RosSender, self.audit_path)
            gateway.configure()
            gateway.activate(operations=True)
            self._stop = gateway.close
        assert gateway.view is not None
        self.view = gateway.view
        return self.view

    def _start_ros(self) -> Gateway:
        import rclpy
        from rclpy.context import Context

        from oricf.gateway.ros.executor import make_executor
        from oricf.gateway.shells.ros import prepare_process
        from oricf.gateway.shells.ros_node import GatewayNode

        prepare_process()  # as `oricf gateway` prepares its process
        context = Context()
        rclpy.init(context=context)
        node = GatewayNode(self.config, context=context, audit_path=self.audit_path)
        node.configure()
        node.activate(operations=True)
        executor = make_executor(self.config.executor_threads, context,
                                 self.config.executor)
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

        self._stop = stop
        return node.gateway

    @staticmethod
    def _spin(executor: Any, context: Any) -> None:
        from oricf.gateway.ros.executor import spin_until_shutdown

        try:
            spin_until_shutdown(executor, context.ok)
        except Exception as exc:  # the tools keep answering; the log says why ROS stopped
            log.error("gateway executor stopped: %s", exc)

    def stop(self) -> None:
        if self._stop is not None:
            stop, self._stop = self._stop, None
            try:
                stop()
            except Exception:
                log.exception("stopping the embedded gateway")
