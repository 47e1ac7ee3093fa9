"""The gateway as a ROS 2 process: rclpy started, the node spun until SIGINT or SIGTERM,
and everything closed in order."""

from __future__ import annotations

import logging
from pathlib import Path

from oricf.gateway.agents.host import serve_gateway_control
from oricf.gateway.config import PipelineConfig
from oricf.gateway.recording.recorder import Recorder
from oricf.gateway.ros.dds import use_dds_profile
from oricf.gateway.ros.executor import make_executor, spin_until_shutdown
from oricf.gateway.ros.params import Settings, declare_settings
from oricf.gateway.ros.process import keep_freed_memory

log = logging.getLogger(__name__)

def run(config: PipelineConfig, ros_args: list[str], record: Path | None = None,
        settings: Settings | None = None) -> int:
    """Spins the node until SIGINT/SIGTERM (rclpy handles both and shuts the context down)."""
    try:
        import rclpy

        from oricf.gateway.ros.rosout import GatewayRosNode
    except ImportError as exc:
        log.error("ROS 2 Python packages not found (%s): source /opt/ros/jazzy/setup.bash, "
                  "or pip install 'oricf[ros]' on x86-64", exc)
        return 2
    use_dds_profile()
    if not keep_freed_memory():
        log.info("mallopt not available: large frame buffers come from fresh pages")
    recorder = Recorder(record) if record is not None else None  # before ROS: fail at once
    rclpy.init(args=ros_args)
    try:
        node = GatewayRosNode(config, recorder=recorder)  # its log on /rosout
    except Exception:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM shut the context down while the node was being built: a stop
        # asked for during start-up, not a failure.
        log.info("gateway stopped while starting")
        if recorder is not None:
            recorder.close()
        rclpy.try_shutdown()
        return 0
    if settings is not None:
        declare_settings(node, settings)
    executor = make_executor(config.executor_threads)
    executor.add_node(node)
    stop_control = serve_gateway_control(node.pipeline, node.outlets.channels)
    try:
        spin_until_shutdown(executor, rclpy.ok)
    finally:
        log.info("gateway stopping")
        stop_control()
        node.shutdown()
        executor.shutdown()
        if recorder is not None:  # complete on disk before DDS is torn down
            recorder.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
