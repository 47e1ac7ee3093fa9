"""Camera routes' own receive threads, outside the rclpy executor.

Per wake-up, rclpy's executors rebuild a wait set of every entity of the node in Python and
run each callback as a task: about 0.5 ms of the robot's CPU per camera frame, as much as
the gRPC call that sends the frame away. A camera route instead gets a thread that waits on
a wait set holding only its subscription and a stop signal (the pattern of rclpy's own
wait_for_message), takes each frame serialized (oricf.gateway.cdr reads it) and runs the
route on it. While the route is busy, DDS keeps only the newest frame (history depth 1);
the frames it replaced are counted from the gaps in the publisher's sequence numbers (exact
with one publisher per camera topic, the usual case; with several the gaps mean nothing and
are not counted).

The subscription belongs to an `OwnThreadGroup`, a callback group that executors never run,
so no executor ever takes from it; text and audio routes stay on the executor.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile

log = logging.getLogger(__name__)

# A safety net only: the stop signal wakes the thread at once.
WAIT_TIMEOUT_NS = 1_000_000_000


class OwnThreadGroup(CallbackGroup):
    """Entities that a thread of their own serves: executors never execute them."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class CameraReceiver:
    """Takes serialized frames from one topic and passes them to `receive` with the number of
    frames missed since the previous one and rclpy's message info (its timestamps)."""

    def __init__(self, node: Node, route: str, msg_type: Any, topic: str, qos: QoSProfile,
                 receive: Callable[[bytes, int, dict[str, Any]], None]) -> None:
        self.route = route
        self._msg_type = msg_type
        self._receive = receive
        self._context = node.context
        self.subscription = node.create_subscription(
            msg_type, topic, _never_called, qos, callback_group=OwnThreadGroup(), raw=True)
        self._wake = GuardCondition(None, None, context=node.context)
        self._stopping = threading.Event()
        self._last_sequence = 0
        self._thread = threading.Thread(target=self._run, name=f"camera-{route}", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, self._context.handle)
        subscription, wake = self.subscription.handle, self._wake.handle
        try:
            while not self._stopping.is_set() and self._context.ok():
                with subscription, wake:  # neither is destroyed while in use here
                    wait_set.clear_entities()
                    wait_set.add_subscription(subscription)
                    wait_set.add_guard_condition(wake)
                    wait_set.wait(WAIT_TIMEOUT_NS)
                    taken = subscription.take_message(self._msg_type, True)
                if taken is not None:
                    serialized, info = taken
                    self._receive(serialized, self._missed(info), info)
        except Exception as exc:  # the context or node went away under the thread
            if not self._stopping.is_set() and self._context.ok():
                log.exception("camera receiver %s stopped", self._thread.name)
            else:
                log.debug("camera receiver %s: %s while stopping", self._thread.name, exc)

    def _missed(self, info: dict[str, Any]) -> int:
        sequence = info.get("publication_sequence_number") or 0
        last, self._last_sequence = self._last_sequence, sequence
        return sequence - last - 1 if 0 < last < sequence else 0

    def stop(self, timeout: float = 5.0) -> None:
        self._stopping.set()
        with contextlib.suppress(Exception):  # gone with its context: the thread ends anyway
            self._wake.trigger()
        if self._thread.is_alive():
            self._thread.join(timeout)
        self._wake.destroy()


def _never_called(msg: Any) -> None:
    raise AssertionError("camera frames are taken by CameraReceiver, not by an executor")
