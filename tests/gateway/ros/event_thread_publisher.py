"""A reliable Int32 publisher that reports how often Fast DDS's event thread woke up.

Run as `python -m tests.gateway.ros.event_thread_publisher TOPIC COUNT` with the environment
of the DDS profile under test: waits for a subscriber, publishes COUNT messages at 50 Hz
and prints {"wakeups": N, "published": COUNT} as JSON. Fast DDS names that thread
`dds.ev.<participant>`; Linux counts its sleeps in /proc (voluntary_ctxt_switches).
"""

from __future__ import annotations

import json
import os
import sys
import time

import rclpy
from rclpy.node import Node
from std_msgs.msg import Int32

from oricf.bench.wakeups import wakeups
from tests.gateway.ros.matching import wait_for_subscriber

RATE_HZ = 50.0
EVENT_THREADS = "dds.ev."  # Fast DDS names its event thread dds.ev.<participant>


def main(topic: str, count: int) -> int:
    rclpy.init()
    node = Node("event_thread_publisher")
    publisher = node.create_publisher(Int32, topic, 10)
    if not wait_for_subscriber(publisher):
        print(json.dumps({"error": "no subscriber matched"}))
        return 1
    time.sleep(1.0)  # discovery traffic settles
    before = wakeups(os.getpid(), EVENT_THREADS)
    for i in range(count):
        publisher.publish(Int32(data=i))
        time.sleep(1.0 / RATE_HZ)
    woken = wakeups(os.getpid(), EVENT_THREADS) - before
    time.sleep(0.5)  # the subscriber gets the last samples before this participant leaves
    print(json.dumps({"wakeups": woken, "published": count}))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], int(sys.argv[2])))
