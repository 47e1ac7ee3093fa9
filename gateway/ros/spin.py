"""The gateway as a ROS 2 process: rclpy started, the node spun until SIGINT or SIGTERM,
and everything closed in order."""

from __future__ import annotations

import logging
from pathlib import Path

from oricf.gateway.config import PipelineConfig
from oricf.gateway.recording.recorder import Recorder
from oricf.gateway.ros.dds import use_dds_profile
from oricf.gateway.ros.executor import make_executor, spin_until_shutdown
from oricf.gateway.ros.params import Settings, declare_settings
from oricf.gateway.ros.process import keep_freed_memory
from oricf.gateway.surfaces import serve_gateway_control
from oricf.signals import stop_on_signals

log = logging.getLogger(__name__)

def run(config: PipelineConfig, ros_args: list[str], record: Path | None = None,
        settings: Settings | None = None) -> int:
    """Spins the node until SIGINT/SIGTERM, then stops in order: the control API and the
    agent's actuation first (the zero command goes out while ROS still runs), the node's
    sources and routes, the recording, and ROS last.

    The signals are ORICF's, not rclpy's: rclpy's handlers shut every context down the
    moment a signal arrives, before the actuation could publish its zero command."""
    try:
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        from oricf.gateway.ros.rosout import GatewayRosNode
    except ImportError as exc:
        log.error("ROS 2 Python packages not found (%s): source /opt/ros/jazzy/setup.bash, "
                  "or pip install 'oricf[ros]' on x86-64", exc)
        return 2
    use_dds_profile()
    if not keep_freed_memory():
        log.info("mallopt not available: large frame buffers come from fresh pages")
    recorder = Recorder(record) if record is not None else None  # before ROS: fail at once
    with stop_on_signals() as stop:
        rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
        node = GatewayRosNode(config, recorder=recorder)  # its log on /rosout
        if stop.is_set():  # SIGINT or SIGTERM came while the node was being built
            node.shutdown()  # its threads, started last in its constructor
            node.destroy_node()
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
            spin_until_shutdown(executor, lambda: not stop.is_set() and rclpy.ok())
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
