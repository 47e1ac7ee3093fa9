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
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import Int32

from oricf.bench.wakeups import wakeups
from tests.gateway.ros.matching import wait_for_subscriber

RATE_HZ = 50.0
ACKED_TIMEOUT_S = 30
EVENT_THREADS = "dds.ev."  # Fast DDS names its event thread dds.ev.<participant>


def main(topic: str, count: int) -> int:
    rclpy.init()
    node = Node("event_thread_publisher")
    # Every sample stays in the writer's history until acknowledged: a reader stalled by a
    # busy machine gets it late, never not at all (KEEP_LAST 10 at 50 Hz dropped samples
    # the reader had not acknowledged within 0.2 s).
    publisher = node.create_publisher(Int32, topic, count)
    if not wait_for_subscriber(publisher):
        print(json.dumps({"error": "no subscriber matched"}))
        return 1
    time.sleep(1.0)  # discovery traffic settles
    before = wakeups(os.getpid(), EVENT_THREADS)
    for i in range(count):
        publisher.publish(Int32(data=i))
        time.sleep(1.0 / RATE_HZ)
    woken = wakeups(os.getpid(), EVENT_THREADS) - before
    # The subscriber has every sample before this participant leaves.
    if not publisher.wait_for_all_acked(Duration(seconds=ACKED_TIMEOUT_S)):
        print(json.dumps({"error": f"not all acknowledged in {ACKED_TIMEOUT_S} s"}))
        return 1
    print(json.dumps({"wakeups": woken, "published": count}))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], int(sys.argv[2])))
