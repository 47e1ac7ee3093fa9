"""LiveView: a pipeline's values to the foxglove-sdk server, without ever holding up a route.

A route hands over each record after its outputs (`show`, in the route's thread). Numbers and
text go out at once: logging a message only queues it for each viewer, and the SDK drops a
slow viewer's oldest messages (`backlog`) rather than wait. A camera frame costs more (a raw
frame is JPEG-encoded), so it only replaces the route's pending frame, and a thread of the
view's own sends at most `max_fps` of them per route, with their detections as annotations,
and only while some viewer is subscribed to the route's image. A frame replaced before it
was sent is lost to the view, never to the robot.

Topics: /ROUTE/image, /ROUTE/detections, /ROUTE/FIELD (numbers and text of the route's
record), /products/NAME, /endpoints/NAME, /routes/ROUTE/state (docs/live-view.md).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import foxglove
from foxglove.channels import CompressedImageChannel, ImageAnnotationsChannel, LogChannel

from oricf.gateway.listeners import LiveViewConfig
from oricf.gateway.live_view import messages
from oricf.gateway.live_view.front import Front
from oricf.gateway.live_view.sdk_logs import make_sdk_logs_safe
from oricf.gateway.recording.recorder import INPUT_TIME
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import FRAME_TIME, Frame, Record

log = logging.getLogger(__name__)

# Record fields that are plumbing, not results: never shown.
HIDDEN_FIELDS = frozenset({"route", "reply_to", "header", FRAME_TIME, INPUT_TIME})
STATE_INTERVAL_S = 1.0
ERROR_LOG_INTERVAL_S = 30.0
States = Callable[[], Iterable[tuple[str, dict[str, Any]]]]
CHANNEL_KINDS: dict[str, Callable[..., Any]] = {
    "image": CompressedImageChannel, "detections": ImageAnnotationsChannel, "log": LogChannel}


@dataclass
class ViewStats:
    frames_sent: int = 0
    frames_replaced: int = 0   # a newer frame came before this one was sent
    frames_unwatched: int = 0  # nobody subscribed to the route's image


@dataclass
class PendingFrame:
    frame: Frame
    detections: list[Any] | None
    ns: int


class LiveView:
    def __init__(self, config: LiveViewConfig, name: str = "oricf") -> None:
        self.config = config
        self.name = name
        self.stats = ViewStats()
        self.front: Front | None = None
        self._context = foxglove.Context()
        self._server: Any = None
        self._channels: dict[str, Any] = {}
        self._lock = threading.Condition()
        self._pending: dict[str, PendingFrame] = {}
        self._next_at: dict[str, float] = {}
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._throttle = ThrottledLog(log, ERROR_LOG_INTERVAL_S)

    @property
    def url(self) -> str:
        return self.front.url if self.front is not None else ""

    def start(self, states: States | None = None) -> None:
        """Opens the SDK's server on loopback and the front on `listen`; a port in use (or a
        certificate or token that cannot be read) is a ConfigError now."""
        make_sdk_logs_safe()
        self._server = foxglove.start_server(
            name=self.name, host="127.0.0.1", port=0, context=self._context,
            message_backlog_size=self.config.backlog)
        try:
            self.front = Front(self.config, self._server.port)
            self.front.start()
        except BaseException:
            self._server.stop()
            raise
        self._start_thread(self._send_frames, "live-view-frames")
        if states is not None:
            self._start_thread(lambda: self._send_states(states), "live-view-states")
        log.info("live view at %s (Foxglove WebSocket protocol)", self.url)

    def _start_thread(self, target: Callable[[], None], name: str) -> None:
        thread = threading.Thread(target=target, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    def declare(self, topic: str, kind: str) -> None:
        """Advertises a topic before its first value (kind: image, detections or log)."""
        self._channel(topic, CHANNEL_KINDS[kind])

    def show(self, route: str, record: Record) -> None:
        """A route's record, in the route's thread: never blocks on a viewer, never raises."""
        try:
            ns = time.time_ns()
            for field, value in record.items():
                if field in HIDDEN_FIELDS or field == "detections":
                    continue
                if isinstance(value, Frame):
                    if field == "image":
                        self._hold_frame(route, value, record.get("detections"), ns)
                else:
                    self._send_value(f"/{route}/{field}", value, route, ns)
        except Exception as exc:  # the view must never cost the route its record
            self._throttle.warning(f"show:{route}:{type(exc).__name__}",
                                   "live view: route %s not shown: %s", route, exc)

    def show_product(self, name: str, value: Any) -> None:
        """A data product's new value (a ProductStore listener)."""
        try:
            self._send_value(f"/products/{name}", value, name, time.time_ns())
        except Exception as exc:
            self._throttle.warning(f"product:{name}:{type(exc).__name__}",
                                   "live view: product %s not shown: %s", name, exc)

    def _send_value(self, topic: str, value: Any, name: str, ns: int) -> None:
        if isinstance(value, str):
            self._channel(topic, LogChannel).log(messages.log_line(value, name, ns), log_time=ns)
            return
        numbers = messages.plottable(value)
        if numbers is not None:
            self._json_channel(topic, numbers).log(numbers, log_time=ns)

    def _hold_frame(self, route: str, frame: Frame, detections: Any, ns: int) -> None:
        if not self._watched(route):  # nobody to send it to: not even the thread is woken
            self.stats.frames_unwatched += 1
            return
        with self._lock:
            if route in self._pending:
                self.stats.frames_replaced += 1
            self._pending[route] = PendingFrame(frame, detections, ns)
            self._lock.notify()

    def _send_frames(self) -> None:
        """The frames thread: each route's newest frame, at most max_fps per route."""
        period = 1.0 / self.config.max_fps
        while not self._stop.is_set():
            with self._lock:
                due = self._due(time.monotonic())
                if due is None:
                    self._lock.wait(self._wait_s(time.monotonic()))
                    continue
                route, pending = due, self._pending.pop(due)
                self._next_at[route] = time.monotonic() + period
            try:
                self._send_frame(route, pending)
            except Exception as exc:
                self._throttle.warning(f"frame:{route}:{type(exc).__name__}",
                                       "live view: a frame of route %s not sent: %s", route,
                                       exc)

    def _due(self, now: float) -> str | None:
        return next((r for r in self._pending if self._next_at.get(r, 0.0) <= now), None)

    def _wait_s(self, now: float) -> float | None:
        """Until the next pending frame is due; None (until notified) if none is pending."""
        times = [self._next_at.get(r, 0.0) - now for r in self._pending]
        return max(0.0, min(times)) if times else None

    def _watched(self, route: str) -> bool:
        """Whether some viewer is subscribed to the route's image or detections."""
        return bool(self._channel(f"/{route}/image", CompressedImageChannel).has_sinks()
                    or self._channel(f"/{route}/detections",
                                     ImageAnnotationsChannel).has_sinks())

    def _send_frame(self, route: str, pending: PendingFrame) -> None:
        images = self._channel(f"/{route}/image", CompressedImageChannel)
        annotations = (self._channel(f"/{route}/detections", ImageAnnotationsChannel)
                       if pending.detections is not None else None)
        if not self._watched(route):  # the viewer left meanwhile
            self.stats.frames_unwatched += 1
            return
        ns = pending.ns
        if images.has_sinks():
            images.log(messages.compressed_image(pending.frame, route, ns,
                                                 self.config.jpeg_quality), log_time=ns)
        if annotations is not None:
            annotations.log(messages.image_annotations(pending.detections or [], ns),
                            log_time=ns)
        self.stats.frames_sent += 1

    def _send_states(self, states: States) -> None:
        while not self._stop.wait(STATE_INTERVAL_S):
            try:
                ns = time.time_ns()
                for topic, state in states():
                    self._json_channel(topic, state).log(state, log_time=ns)
            except Exception as exc:
                self._throttle.warning(f"states:{type(exc).__name__}",
                                       "live view: states not sent: %s", exc)

    def _channel(self, topic: str, kind: Callable[..., Any]) -> Any:
        with self._lock:
            if topic not in self._channels:
                self._channels[topic] = kind(topic, context=self._context)
            return self._channels[topic]

    def _json_channel(self, topic: str, first: dict[str, Any]) -> Any:
        with self._lock:
            if topic not in self._channels:
                self._channels[topic] = foxglove.Channel(
                    topic, schema=messages.json_channel_schema(topic, first),
                    message_encoding="json", context=self._context)
            return self._channels[topic]

    def stop(self) -> None:
        self._stop.set()
        with self._lock:
            self._lock.notify_all()
        for thread in self._threads:
            thread.join(timeout=5)
        if self.front is not None:
            self.front.close()
        if self._server is not None:
            self._server.stop()
        log.info("live view closed: %d frames sent, %d replaced before sending, %d unwatched",
                 self.stats.frames_sent, self.stats.frames_replaced,
                 self.stats.frames_unwatched)


