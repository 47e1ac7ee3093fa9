"""The gateway as a ROS 2 process: rclpy started, the node configured, activated (or left
for a lifecycle manager to) and spun until SIGINT, SIGTERM or its shutdown transition, and
everything closed in order."""

from __future__ import annotations

import importlib
import logging
from pathlib import Path
from typing import TYPE_CHECKING

from oricf.gateway.config import PipelineConfig
from oricf.gateway.recording.recorder import Recorder
from oricf.gateway.ros.dds import use_dds_profile
from oricf.gateway.ros.executor import make_executor, require_executor, spin_until_shutdown
from oricf.gateway.ros.params import Settings, declare_settings
from oricf.gateway.ros.process import keep_freed_memory
from oricf.signals import stop_on_signals

if TYPE_CHECKING:
    from rclpy.context import Context

    from oricf.gateway.shells.ros_node import GatewayNode

log = logging.getLogger(__name__)


def prepare_process() -> None:
    """What a process does before rclpy starts: ORICF's DDS profile, and freed memory kept
    for the next frame's buffers."""
    use_dds_profile()
    if not keep_freed_memory():
        log.info("mallopt not available: large frame buffers come from fresh pages")


def gateway_ros_node(config: PipelineConfig, recorder: Recorder | None = None,
                     context: Context | None = None) -> GatewayNode:
    """The gateway node as `oricf gateway` and `ros2 run oricf_gateway gateway` run it: its
    log on /rosout from the moment the node exists."""
    from oricf.gateway.ros.rosout import RosoutLogging
    from oricf.gateway.shells.ros_node import GatewayNode

    class GatewayRosNode(GatewayNode, RosoutLogging):
        """RosoutLogging's destroy_node comes before Node's; its __init__ is not reached
        (rclpy's LifecycleNode calls Node.__init__ by name), so it is attached here."""

        def __init__(self) -> None:
            GatewayNode.__init__(self, config, context=context, recorder=recorder)
            self.attach_rosout()

    return GatewayRosNode()


def run(config: PipelineConfig, ros_args: list[str], record: Path | None = None,
        settings: Settings | None = None, autostart: bool = True) -> int:
    """Spins the node until SIGINT/SIGTERM, or until a lifecycle manager shuts it down
    (finalized), then stops in order: the control API and the agent's actuation first (the
    zero command goes out while ROS still runs), the node's inputs and routes, the
    recording, and ROS last. With `autostart` the node configures and activates itself;
    without, it waits unconfigured for `ros2 lifecycle set` or a lifecycle manager.

    The signals are ORICF's, not rclpy's: rclpy's handlers shut every context down the
    moment a signal arrives, before the actuation could publish its zero command."""
    try:  # rclpy and the message packages the node needs
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        for module in ("oricf.gateway.ros.rosout", "oricf.gateway.shells.ros_node"):
            importlib.import_module(module)
    except ImportError as exc:
        log.error("ROS 2 Python packages not found (%s): source /opt/ros/jazzy/setup.bash, "
                  "or pip install 'oricf[ros]' on x86-64", exc)
        return 2
    prepare_process()
    require_executor(config.executor)  # before ROS: fail at once
    recorder = Recorder(record) if record is not None else None
    with stop_on_signals() as stop:
        rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
        executor = make_executor(config.executor_threads, kind=config.executor)
        node = gateway_ros_node(config, recorder)
        try:
            if settings is not None:
                declare_settings(node, settings)
            if autostart:
                node.configure()
                if stop.is_set():  # SIGINT or SIGTERM came while the node was configured
                    log.info("gateway stopped while starting")
                    return 0
                node.activate()
            else:
                log.info("gateway node %s: unconfigured, for its lifecycle manager to "
                         "configure and activate", node.get_name())
            executor.add_node(node)
            try:
                spin_until_shutdown(executor, lambda: not stop.is_set() and rclpy.ok()
                                    and node.state != "finalized")
            finally:
                log.info("gateway stopping")
                node.deactivate()
                executor.shutdown()
        finally:
            node.shutdown()
            if recorder is not None:  # complete on disk before DDS is torn down
                recorder.close()
            node.destroy_node()
            rclpy.try_shutdown()
    return 0
