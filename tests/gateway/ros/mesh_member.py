"""One process of a DDS mesh: publishes its index, subscribes to every other member's.

Run as `python -m tests.gateway.ros.mesh_member INDEX TOTAL oricf|plain`: `oricf` sets up
Fast DDS as ORICF's processes do (oricf.gateway.ros.dds.use_dds_profile), `plain` takes the
environment as it is, as a node ORICF did not write.
Publishes on /mesh/member_INDEX five times a second, prints `heard [...]` (JSON) whenever
another member is heard for the first time, and goes on publishing (so the others hear it
too) until its standard input closes. Then prints one JSON object: the members it heard,
the UDP and TCP sockets it held, and those bound to an address other hosts can reach.
"""

from __future__ import annotations

import json
import os
import sys
import threading

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String

from oricf.gateway.ros.dds import use_dds_profile
from tests.support.sockets import inet_sockets

PERIOD_S = 0.2


def topic(index: int) -> str:
    return f"/mesh/member_{index}"


def stdin_closed() -> threading.Event:
    closed = threading.Event()

    def wait() -> None:
        sys.stdin.read()
        closed.set()

    threading.Thread(target=wait, daemon=True).start()
    return closed


def main(index: int, total: int, kind: str) -> int:
    if kind == "oricf":
        use_dds_profile()
    context = Context()
    rclpy.init(context=context)
    node = Node(f"mesh_member_{index}", context=context)
    heard: set[int] = set()
    publisher = node.create_publisher(String, topic(index), 10)
    for other in range(total):
        if other != index:
            node.create_subscription(String, topic(other),
                                     lambda msg: heard.add(int(msg.data)), 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    closed = stdin_closed()
    announced = 0
    while not closed.is_set():
        publisher.publish(String(data=str(index)))
        executor.spin_once(timeout_sec=PERIOD_S)
        if len(heard) > announced:
            announced = len(heard)
            print("heard", json.dumps(sorted(heard)), flush=True)
    sockets = inet_sockets(os.getpid())
    print(json.dumps({"index": index, "heard": sorted(heard),
                      "sockets": [str(s) for s in sockets],
                      "off_loopback": [str(s) for s in sockets if not s.loopback]}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=context)
    return 0


if __name__ == "__main__":
    sys.exit(main(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]))
