"""The gateway node's Python log on /rosout, read by a subscriber on real DDS."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
import rclpy.logging
from rcl_interfaces.msg import Log
from rclpy.context import Context

from oricf.gateway.shells.ros import gateway_ros_node
from oricf.gateway.shells.ros_node import GatewayNode
from tests.gateway.pipelines import people_qa
from tests.gateway.ros.rosout import lines_until, next_line, rosout_reader

NOWHERE = {name: "127.0.0.1:9" for name in ("detector", "asr", "llm")}  # nothing listens


@contextmanager
def gateway_node(context: Context, name: str) -> Iterator[GatewayNode]:
    node = gateway_ros_node(people_qa({"node_name": name}, **NOWHERE), context=context)
    try:
        node.configure()
        node.activate()
        yield node
    finally:
        node.shutdown()
        node.destroy_node()


def test_the_gateway_log_reaches_rosout_once_with_level_and_place(
        ros_context: Context, capfd: pytest.CaptureFixture[str]) -> None:
    with rosout_reader(ros_context) as lines, gateway_node(ros_context, "rosout_gw") as node:
        started = next_line(lines, "rosout_gw", "gateway node rosout_gw: 4 routes")
        logging.getLogger("oricf.gateway.test").warning("a warning from %s", "the test")
        warned = next_line(lines, "rosout_gw", "a warning from the test")
        logging.getLogger("oricf.gateway.test").debug("below INFO")
        logging.getLogger("elsewhere").warning("not the gateway's")
        # The node's own logger, through the same /rosout writer: after the two above.
        node.get_logger().info("marker")
        between = [line.msg for line in lines_until(lines, "rosout_gw", "marker")
                   if line.name == "rosout_gw"]
    assert between == ["marker"]
    assert (started.level, started.function) == (Log.INFO, "_activate")
    assert started.file.endswith("gateway/shells/ros_node.py")
    assert (warned.level, warned.function) == (Log.WARN, "test_the_gateway_log_reaches_rosout_"
                                                         "once_with_level_and_place")
    console = capfd.readouterr().err
    # printed once, by rcutils, not a second time by Python's root handler
    assert console.count("gateway node rosout_gw: 4 routes") == 1
    assert "[rosout_gw]: gateway node rosout_gw: 4 routes" in console


def test_the_ros_log_level_sets_the_gateway_level(ros_context: Context) -> None:
    rclpy.logging.set_logger_level("debug_gw", rclpy.logging.LoggingSeverity.DEBUG)
    try:
        with rosout_reader(ros_context) as lines, gateway_node(ros_context, "debug_gw"):
            logging.getLogger("oricf.gateway.test").debug("a debug line")
            assert next_line(lines, "debug_gw", "a debug line").level == Log.DEBUG
    finally:
        rclpy.logging.set_logger_level("debug_gw", rclpy.logging.LoggingSeverity.INFO)


def test_a_namespaced_node_logs_under_its_full_name(ros_env: dict[str, str]) -> None:
    context = Context()
    rclpy.init(args=["gw", "--ros-args", "-r", "__ns:=/robot3"], context=context)
    try:
        with rosout_reader(context) as lines, gateway_node(context, "ns_gw"):
            assert next_line(lines, "robot3.ns_gw", "gateway node ns_gw").level == Log.INFO
    finally:
        rclpy.try_shutdown(context=context)


def test_python_logging_is_back_after_shutdown_and_destroy(
        ros_env: dict[str, str], caplog: pytest.LogCaptureFixture,
        capfd: pytest.CaptureFixture[str]) -> None:
    context = Context()
    rclpy.init(context=context)
    oricf = logging.getLogger("oricf")
    before = oricf.level, oricf.propagate
    with gateway_node(context, "closing_gw"):
        assert not oricf.propagate
        rclpy.shutdown(context=context)  # what SIGTERM does
        with caplog.at_level(logging.INFO, logger="oricf"):
            logging.getLogger("oricf.gateway.test").info("after the context")
    assert "after the context" in caplog.text  # handed to the root handlers instead
    assert "Failed to publish log message to rosout" not in capfd.readouterr().err
    assert (oricf.level, oricf.propagate) == before
    assert not any(type(h).__name__ == "RosoutHandler" for h in oricf.handlers)
