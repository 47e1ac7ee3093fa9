"""Camera routes' own receive threads, outside the rclpy executor.

Per wake-up, rclpy's executors rebuild a wait set of every entity of the node in Python and
run each callback as a task, which costs the robot as much CPU per camera frame as the
gRPC call that sends the frame away (docs/ros.md). A camera route instead gets a thread
that waits on a wait set holding only its subscription and a stop signal (the pattern of
rclpy's own wait_for_message), takes each frame serialized (the topic codec,
oricf.gateway.topics.codec, reads it) and runs the route on it. While the route is busy,
DDS keeps only the newest frame (history depth 1); the frames it replaced are counted from
the gaps in the publisher's sequence numbers (exact with one publisher per camera topic, the
usual case; with several the gaps mean nothing and are not counted).

Camera drivers are not ours, and the subscription adapts to them. Its reliability follows the
topic's publishers, checked every second: reliable when every publisher is (image_transport's
default, reliable with depth 10, which many drivers keep), so DDS resends the pieces of a raw
frame lost on the way; best effort as soon as one publisher is (sensor_data drivers), since a
reliable subscription would not match it. A gap that the route's busy time cannot explain
is frames lost on the way, not replaced (oricf.gateway.ros.frame_loss): when those are many, or
when a publisher never matches, the receiver warns once, naming what to set where the camera
is started (docs/ros.md, Camera drivers).

The subscription belongs to an `OwnThreadGroup`, a callback group that executors never run,
so no executor ever takes from it; text and audio routes stay on the executor.
"""

from __future__ import annotations

import contextlib
import copy
import logging
import threading
import time
from collections.abc import Sequence
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from oricf.gateway.config import InputConfig
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.recording.recorder import Recorder, message_times
from oricf.gateway.ros.frame_loss import FrameLoss, camera_side_fix, replaceable
from oricf.gateway.ros.messages import message_type
from oricf.gateway.topics.codec import input_loader, timed

log = logging.getLogger(__name__)

# A safety net only: the stop signal wakes the thread at once.
WAIT_TIMEOUT_NS = 1_000_000_000
# How often the topic's publishers are looked up again (a camera started after the gateway,
# or restarted with other QoS).
PUBLISHER_CHECK_S = 1.0
# Discovery matches a publisher within a second or two; one unmatched for longer never will.
UNMATCHED_WARN_S = 5.0


class OwnThreadGroup(CallbackGroup):
    """Entities that a thread of their own serves: executors never execute them."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class CameraReceiver:
    """Takes serialized frames from one topic and runs the route on each in this thread (the
    pipeline's handle_here), with the number of frames missed since the previous one; with
    a recorder, each frame is recorded first. `qos` gives the depth and the reliability to
    start with, until publishers are found."""

    def __init__(self, node: Node, route: str, config: InputConfig, qos: QoSProfile,
                 pipeline: Pipeline, recorder: Recorder | None = None) -> None:
        assert config.topic is not None and config.type is not None
        self.route = route
        self.loss = FrameLoss()
        self._node = node
        self._type = config.type
        self._msg_type = message_type(config.type)
        self._topic = config.topic
        self._name = node.resolve_topic_name(config.topic)
        self._qos = qos
        self._pipeline = pipeline
        self._recorder = recorder
        self._context = node.context
        self.subscription = self._subscribe(qos.reliability)
        self._wake = GuardCondition(None, None, context=node.context)
        self._stopping = threading.Event()
        self._last_sequence = 0
        self._last_source = 0  # the previous frame's source timestamp (ns)
        self._last_take = 0.0  # when the previous frame was taken (monotonic s)
        self._publishers = 1  # until looked up
        self._next_check = 0.0
        self._unmatched_since: float | None = None
        self._unmatched_warned = False
        self._thread = threading.Thread(target=self._run, name=f"camera-{route}", daemon=True)

    @property
    def reliability(self) -> ReliabilityPolicy:
        return ReliabilityPolicy(self.subscription.qos_profile.reliability)

    def start(self) -> None:
        self._thread.start()

    def _subscribe(self, reliability: ReliabilityPolicy) -> Any:
        qos = copy.copy(self._qos)
        qos.reliability = reliability
        return self._node.create_subscription(
            self._msg_type, self._topic, _never_called, qos, callback_group=OwnThreadGroup(),
            raw=True)

    def _run(self) -> None:
        try:
            handle = self._context.handle
            if handle is None:  # the context was shut down before the thread ran
                return
            wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, handle)
            while not self._stopping.is_set() and self._context.ok():
                if time.monotonic() >= self._next_check:
                    self._match_publishers()
                taken, waited = self._take(wait_set)
                if taken is not None:
                    serialized, info = taken
                    self._receive(serialized, self._count(len(serialized), info, waited), info)
        except Exception as exc:  # the context or node went away under the thread
            if not self._stopping.is_set() and self._context.ok():
                log.exception("camera receiver %s stopped", self._thread.name)
            else:
                log.debug("camera receiver %s: %s while stopping", self._thread.name, exc)

    def _receive(self, serialized: bytes, missed: int, info: dict[str, Any]) -> None:
        # Taken when stamped, or else when it arrived (as a recording logs it).
        load = timed(input_loader(self._type, serialized), message_times(info)[0])
        if self._recorder is not None:
            load = self._recorder.input(self._name, self._type, serialized,
                                        *message_times(info), load)
        self._pipeline.handle_here(self.route, load, missed)

    def _take(self, wait_set: Any) -> tuple[Any, bool]:
        """The next frame, if one came within the wait, and whether the receiver was idle
        waiting for it (a frame already there was taken without waiting)."""
        subscription, wake = self.subscription.handle, self._wake.handle
        with subscription, wake:  # neither is destroyed while in use here
            taken = subscription.take_message(self._msg_type, True)
            if taken is not None:
                return taken, False
            wait_set.clear_entities()
            wait_set.add_subscription(subscription)
            wait_set.add_guard_condition(wake)
            wait_set.wait(WAIT_TIMEOUT_NS)
            return subscription.take_message(self._msg_type, True), True

    def _count(self, size: int, info: dict[str, Any], waited: bool) -> int:
        """Frames replaced while the route was busy; frames lost on the way are counted in
        `loss` only (they never reached the gateway, so the route never dropped them)."""
        now, source = time.monotonic(), info.get("source_timestamp") or 0
        busy_s, span_s = now - self._last_take, (source - self._last_source) / 1e9
        self._last_take, self._last_source = now, source
        gap = self._missed(info)
        # A reliable subscription gets every frame (DDS resends what was lost): a gap is
        # frames replaced, whenever they arrived (repaired frames come in bunches).
        reliable = self.reliability == ReliabilityPolicy.RELIABLE
        replaced = self.loss.add(gap, gap if reliable else
                                 replaceable(gap, waited, busy_s, span_s))
        # Before warning, look at the publishers again: one that became reliable since the
        # last look explains the losses, and the new subscription ends them.
        if self.loss.warning_due and not self._match_publishers():
            self._warn_lost(size)
        return replaced

    def _missed(self, info: dict[str, Any]) -> int:
        sequence = info.get("publication_sequence_number") or 0
        last, self._last_sequence = self._last_sequence, sequence
        if self._publishers > 1:
            return 0
        return sequence - last - 1 if 0 < last < sequence else 0

    def _match_publishers(self) -> bool:
        """Subscribes again if the topic's publishers call for another reliability; True if
        it did."""
        now = time.monotonic()
        self._next_check = now + PUBLISHER_CHECK_S
        publishers = self._node.get_publishers_info_by_topic(self.subscription.topic_name)
        self._publishers = len(publishers)
        offered = [p.qos_profile.reliability for p in publishers]
        wanted = matching_reliability(offered)
        if wanted is None or wanted == self.reliability:
            self._check_matched(publishers, now)
            return False
        old, self.subscription = self.subscription, self._subscribe(wanted)
        self._node.destroy_subscription(old)
        self._last_sequence = 0
        self.loss.restart()
        self._unmatched_since = None
        log.info("route %s: %s has %d publisher(s), %s: the subscription is now %s, depth %d",
                 self.route, self.subscription.topic_name, len(publishers),
                 ", ".join(sorted({_name(r) for r in offered})), _name(wanted), self._qos.depth)
        return True

    def _check_matched(self, publishers: list[Any], now: float) -> None:
        """Warns once when publishers stay unmatched: their frames never come, not one lost
        frame shows it, and nothing else would say so."""
        if self.subscription.get_publisher_count() >= len(publishers):
            self._unmatched_since = None
            return
        if self._unmatched_since is None:
            self._unmatched_since = now
        if self._unmatched_warned or now - self._unmatched_since < UNMATCHED_WARN_S:
            return
        self._unmatched_warned = True
        log.warning(
            "route %s: %s has %d publisher(s) (%s) but the gateway's subscription (%s) matched "
            "%d in %.0f s: frames from the others never arrive. Check the message type. "
            "See docs/ros.md, Camera drivers",
            self.route, self.subscription.topic_name, len(publishers),
            ", ".join(f"{p.node_namespace.rstrip('/')}/{p.node_name}: {p.topic_type}, "
                      f"{_name(p.qos_profile.reliability)}" for p in publishers),
            _type_name(self._msg_type), self.subscription.get_publisher_count(),
            now - self._unmatched_since)

    def _warn_lost(self, frame_bytes: int) -> None:
        self.loss.warned = True
        log.warning("route %s: %d of the %d frames published on %s never arrived (frames of "
                    "%s bytes, lost in DDS before the gateway got them: the publisher is best "
                    "effort, so DDS never resends a lost piece of a frame). %s", self.route,
                    self.loss.lost, self.loss.published, self.subscription.topic_name,
                    f"{frame_bytes:,}", camera_side_fix(frame_bytes))

    def stop(self, timeout: float = 5.0) -> None:
        self._stopping.set()
        with contextlib.suppress(Exception):  # gone with its context: the thread ends anyway
            self._wake.trigger()
        if self._thread.is_alive():
            self._thread.join(timeout)
        self._wake.destroy()


def matching_reliability(offered: Sequence[ReliabilityPolicy]) -> ReliabilityPolicy | None:
    """Reliable when every publisher is, so DDS resends the lost pieces of a frame; best
    effort when any is not, since a reliable subscription would not match it; None without
    publishers (the subscription stays as it is)."""
    if not offered:
        return None
    if all(reliability == ReliabilityPolicy.RELIABLE for reliability in offered):
        return ReliabilityPolicy.RELIABLE
    return ReliabilityPolicy.BEST_EFFORT


def _name(reliability: ReliabilityPolicy) -> str:
    return "reliable" if reliability == ReliabilityPolicy.RELIABLE else "best effort"


def _type_name(msg_type: Any) -> str:
    """package/msg/Type, as the ROS graph names types."""
    package = msg_type.__module__.split(".")[0]
    return f"{package}/msg/{msg_type.__name__}"


def _never_called(msg: Any) -> None:
    raise AssertionError("camera frames are taken by CameraReceiver, not by an executor")
