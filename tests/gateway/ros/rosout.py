"""Reading /rosout on real DDS: what a robot's log tools (rqt_console, ros2 topic echo) see."""

from __future__ import annotations

import queue
from collections.abc import Iterator
from contextlib import contextmanager

from rcl_interfaces.msg import Log
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from tests.gateway.ros.gateway_node import spinning

# As rcl publishes it: reliable, and kept for late subscribers.
ROSOUT_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


@contextmanager
def rosout_reader(context: Context) -> Iterator[queue.Queue[Log]]:
    """Every line published on /rosout while the block runs, in a queue."""
    node = Node("rosout_reader", context=context)
    lines: queue.Queue[Log] = queue.Queue()
    node.create_subscription(Log, "/rosout", lines.put, ROSOUT_QOS)
    try:
        with spinning(context, node):
            yield lines
    finally:
        node.destroy_node()


def lines_until(lines: queue.Queue[Log], name: str, text: str, timeout: float = 10
                ) -> list[Log]:
    """The lines that arrive up to the first of logger `name` containing `text`, that one
    last."""
    read: list[Log] = []
    while not read or read[-1].name != name or text not in read[-1].msg:
        read.append(lines.get(timeout=timeout))
    return read


def next_line(lines: queue.Queue[Log], name: str, text: str, timeout: float = 10) -> Log:
    return lines_until(lines, name, text, timeout)[-1]
