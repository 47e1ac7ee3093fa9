"""control: a route that ticks at the policy's rate instead of once per message: the
observation assembled from the newest state messages, a request to the route's policy
(`call: {method: Act}`) when the queue runs short, one action a tick through the target's
policy (bounds, rate, deadman), the safe action when nothing is queued.

    routes:
      arm:
        input:
          control:
            rate_hz: 80
            state: [{topic: /arm/joint_states, type: sensor_msgs/JointState,
                     fields: [position, velocity]}]
            images: [{name: wrist, topic: /arm/wrist/image_raw}]   # the policy's cameras
            max_age_ms: 50          # an older state part: nothing is asked
            action_dim: 4
            safe_action: [0, 0, 0, 0]
            request_at: 6           # ask when this many actions are left queued
            deadline_steps: 12      # ask again when an answer is this late
            max_ahead_ms: 500       # the policy's horizon: no action planned further ahead
            late: skip              # or shift (oricf.gateway.actions.queue)
            merge: ensemble         # latest, weighted or ensemble
            target: {topic: /arm/command, type: std_msgs/Float64MultiArray,
                     bounds: [[-1, 1], [-1, 1], [-1, 1], [-1, 1]], deadman_ms: 100}
        call: {method: Act, service: arm_policy}

The loop's logic is oricf.gateway.actions.loop; this runs it on the robot's clock (a thread
that ticks on an absolute schedule, so a late tick does not shift the ones after it: steps
are time) and hands its requests to the route, whose answer comes back through `reply_to`.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from oricf.config import Schema
from oricf.errors import ConfigError
from oricf.gateway.actions.loop import ControlLoop, Request
from oricf.gateway.actions.observation import CameraPart, MissingState, Observation, StatePart
from oricf.gateway.actions.queue import MAX_AHEAD, ActionQueue, BadChunk, Origin
from oricf.gateway.actions.target import ActionTarget, ActionTargetConfig
from oricf.gateway.components import ComponentContext, OnEnd, Source, SourceKind, Submit
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import Frame, Record, compressed_frame, raw_frame

log = logging.getLogger(__name__)


class ControlSettings(Schema):
    rate_hz: float = Field(gt=0, le=1000, description="ticks a second (the policy's rate)")
    tick: Literal["clock", "state"] = Field(
        "clock", description="clock: the loop ticks on its own clock at rate_hz; state: each "
        "message of the first state part is a step (the robot's own clock), and its action "
        "goes out as soon as it is known: at once when queued, else when the answer to that "
        "state comes (or with the next state)")
    state: list[StatePart] = Field(min_length=1, max_length=32)
    images: list[CameraPart] = Field(
        default_factory=list, max_length=8,
        description="the policy's cameras: the newest image of each goes with the state")
    max_age_ms: float = Field(100.0, gt=0, le=10_000)
    action_dim: int = Field(ge=1, le=4096)
    safe_action: list[float] | None = Field(None, description="sent when nothing is "
                                            "queued (default: zeros)")
    hold_steps: int = Field(0, ge=0, le=10_000, description="ticks the last action is "
                            "repeated before the safe action")
    request_at: int = Field(0, ge=0, le=10_000)
    deadline_steps: int = Field(10, ge=1, le=100_000)
    max_in_flight: int = Field(1, ge=1, le=64)
    max_ahead_ms: float | None = Field(
        None, gt=0, le=600_000, description="the policy's horizon: an action for a step "
        "further than this after the observation it answers is dropped, and a chunk that "
        "starts there refused (default: one second, or one step where a step is longer)")
    late: Literal["skip", "shift"] = "skip"
    merge: Literal["latest", "weighted", "ensemble"] = "latest"
    send_committed: bool = False
    target: ActionTargetConfig

    @model_validator(mode="after")
    def _consistent(self) -> ControlSettings:
        if self.safe_action is not None and len(self.safe_action) != self.action_dim:
            raise ValueError(f"safe_action: {len(self.safe_action)} values for action_dim "
                             f"{self.action_dim}")
        names = [camera.name for camera in self.images]
        if len(set(names)) != len(names):
            raise ValueError(f"images: a camera is named twice ({', '.join(names)})")
        if not 1 <= self.ahead_steps() <= MAX_AHEAD:
            raise ValueError(f"max_ahead_ms: {self.max_ahead_ms:g} ms is "
                             f"{self.ahead_steps()} steps at {self.rate_hz:g} Hz: from one "
                             f"step to {MAX_AHEAD}")
        size = self.target.size()
        if size is not None and size != self.action_dim:
            raise ValueError(f"target: its joints, fields or bounds give {size} values for "
                             f"action_dim {self.action_dim}")
        return self

    def safe(self) -> np.ndarray:
        return np.asarray(self.safe_action or [0.0] * self.action_dim, np.float64)

    def ahead_steps(self) -> int:
        """The policy's horizon in whole steps at `rate_hz` (the queue's `horizon`): by
        default one second, or one step where a step is longer."""
        if self.max_ahead_ms is None:
            return max(1, math.floor(self.rate_hz + 1e-6))
        # The tolerance keeps 1000 ms at 60.606 Hz 60 steps, not 59.
        return math.floor(self.max_ahead_ms * self.rate_hz / 1000 + 1e-6)


class ControlInput(Schema):
    control: ControlSettings | None = None


class Asked:
    """One request as the route's loader; the route tells it its answer or its failure, on
    the route's worker thread, which also made the call: the CPU of the whole request on
    the robot (the record, the call's message, the gRPC call on that thread, taking the
    answer) is that thread's between the two."""

    def __init__(self, source: ControlSource, request: Request) -> None:
        self.source = source
        self.request = request
        self._started_cpu_ns = 0

    def __call__(self) -> Record:
        self._started_cpu_ns = time.thread_time_ns()
        request = self.request
        return {"state": request.state, "step": request.step,
                "capture_time_ns": request.capture_time_ns, "committed": request.committed,
                "images": request.images, "reply_to": self}

    def answered(self, record: Record) -> None:
        self.source.answered(self.request, record)
        self._spent()

    def fail(self, message: str) -> None:
        self.source.failed(self.request, message)
        self._spent()

    def _spent(self) -> None:
        if self._started_cpu_ns:
            self.source.loop.counts.request_cpu_ns += time.thread_time_ns() - self._started_cpu_ns

    def on_drop(self, reason: str) -> None:
        self.source.failed(self.request, reason)


class ControlSource:
    def __init__(self, route: str, settings: ControlSettings, submit: Submit,
                 context: ComponentContext) -> None:
        if context.topics is None:
            raise ConfigError(f"routes.{route}.input.control: reads and writes ROS topics: "
                              f"run the gateway with ROS")
        self.route = route
        self.settings = settings
        queue = ActionQueue(settings.action_dim, settings.late, settings.merge,
                            horizon=settings.ahead_steps())
        self.loop = ControlLoop(queue, settings.safe(), settings.request_at,
                                settings.deadline_steps, settings.hold_steps,
                                settings.send_committed, settings.max_in_flight)
        self.observation = Observation(settings.state, _state_size(settings),
                                       settings.max_age_ms, settings.images, camera_frame)
        self.target = ActionTarget(settings.target, context.topics.publisher(
            settings.target.topic, settings.target.type), settings.safe())
        for index, part in enumerate(settings.state):
            context.topics.subscribe(part.topic, part.type, self._taker(index))
        for index, camera in enumerate(settings.images):
            context.topics.subscribe(camera.topic, camera.type, self._image_taker(index))
        context.loops[route] = self.loop
        self._submit = submit
        self._throttle = ThrottledLog(log)
        self._acted = -1
        self._step = -1                     # tick: state: the newest state's step
        self._pending: int | None = None    # tick: state: a step whose action awaits its answer
        self._last_state_ns = 0             # tick: state: when the newest state came
        self._lock = threading.Lock()       # tick: state: states and answers, one at a time
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name=f"control-{route}")

    def _taker(self, index: int) -> Any:
        ticks = index == 0 and self.settings.tick == "state"

        def take(msg: Any) -> None:
            cpu = time.thread_time_ns()
            try:
                self.observation.take(index, msg)
            except MissingState as exc:
                self._throttle.warning(f"state:{index}", "route %s: state refused: %s",
                                       self.route, exc)
            self.loop.counts.tick_cpu_ns += time.thread_time_ns() - cpu
            if ticks and not self._stop.is_set():
                self._on_state()
        return take

    def _image_taker(self, index: int) -> Any:
        def take(msg: Any) -> None:
            cpu = time.thread_time_ns()
            try:
                self.observation.take_image(index, msg)
            except MissingState as exc:
                self._throttle.warning(f"image:{index}", "route %s: image refused: %s",
                                       self.route, exc)
            self.loop.counts.tick_cpu_ns += time.thread_time_ns() - cpu
        return take

    def start(self) -> None:
        log.info("route %s: control loop at %g Hz (ticked by its %s) -> %s (%s)", self.route,
                 self.settings.rate_hz, self.settings.tick, self.settings.target.topic,
                 self.settings.target.type)
        if self.settings.tick == "clock":
            self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stops ticking; the target's last message is the safe action."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)
        with self._lock:  # no state or answer acts after this
            self.loop.stop()
            self.target.close()

    def _run(self) -> None:
        period = 1.0 / self.settings.rate_hz
        started = time.monotonic()
        step = 0
        while not self._stop.is_set():
            cpu = time.thread_time_ns()
            self._tick(step)
            self.loop.counts.tick_cpu_ns += time.thread_time_ns() - cpu
            step += 1
            due = started + step * period
            wait = due - time.monotonic()
            if wait < 0:  # behind: the steps whose time passed are not played
                missed = int(-wait / period)
                self.loop.counts.late_ticks += 1
                step += missed
                wait += missed * period
            self._stop.wait(max(0.0, wait))

    def _tick(self, step: int) -> None:
        self._ask(step)
        self._act(step)

    def _ask(self, step: int) -> bool:
        """Sends the observation to the policy if the loop asks for it now; whether it did."""
        try:
            observed = self.observation.assemble(time.monotonic_ns())
        except MissingState as exc:
            self.loop.counts.missing_state += 1
            self._throttle.warning("missing", "route %s: no observation: %s", self.route, exc)
            return False
        request = self.loop.ask(step, observed.state, observed.received_ns,
                                observed.images or None)
        if request is not None:
            self._submit(Asked(self, request))
        return request is not None

    def _act(self, step: int) -> None:
        tick = self.loop.act(step, time.monotonic_ns())
        self._acted = step
        self.target.send(tick.action)

    def _on_state(self) -> None:
        """tick: state: a new step. The step before it, if still waiting for its answer,
        is acted on now (held or safe); this one at once when an action is queued for it,
        else when its answer comes."""
        cpu = time.thread_time_ns()
        try:
            self._step_on_state()
        finally:
            self.loop.counts.tick_cpu_ns += time.thread_time_ns() - cpu

    def _step_on_state(self) -> None:
        now = time.monotonic_ns()
        with self._lock:
            if self._stop.is_set():
                return
            silent_ns = now - self._last_state_ns
            self._last_state_ns = now
            if self._step >= 0 and silent_ns > self.observation.max_age_ns:
                # The loop did not tick while the robot was silent: what it queued, held or
                # asked before was planned for a robot that has moved on since.
                self._pending = None
                self.loop.restart()
                self._throttle.warning("restart", "route %s: the robot's state came back after "
                                       "%.0f ms: the actions queued before it dropped",
                                       self.route, silent_ns / 1e6)
            if self._pending is not None:
                self._act(self._pending)
                self._pending = None
            self._step += 1
            asked = self._ask(self._step)
            if asked and self.loop.queue.remaining(self._step) == 0:
                self._pending = self._step
            else:
                self._act(self._step)

    def answered(self, request: Request, record: Record) -> None:
        queued = self._queue_answer(request, record)
        with self._lock:
            if self._pending == request.step and not self._stop.is_set():
                self._act(request.step)  # the action of the state this answers, at once
                self._pending = None
        if queued == 0 and self.settings.late == "skip":
            self._throttle.warning(
                "stale", "route %s: a chunk for step %d came at step %d, after all its "
                "actions' steps (late: shift plays a chunk from its arrival; a longer chunk "
                "or a policy placed nearer keeps to time)", self.route, request.step,
                self._acted)

    def _queue_answer(self, request: Request, record: Record) -> int | None:
        """The answer's actions queued as the answer to `request`, the observation this
        call sent: how many (None: refused). An answer that names another observation is
        not trusted with this one's."""
        said = int(record["observation_step"])
        if said != request.step:
            self.loop.refuse(request.step)
            self._throttle.warning("mismatch", "route %s: the answer to the observation of "
                                   "step %d says it answers step %d: refused", self.route,
                                   request.step, said)
            return None
        origin = Origin(request.step, request.capture_time_ns)
        try:
            return self.loop.deliver(record["actions"], int(record["start_step"]), origin,
                                     now=self._acted)
        except BadChunk as exc:
            self._throttle.warning("bad_chunk", "route %s: chunk refused: %s", self.route, exc)
            return None

    def failed(self, request: Request, message: str) -> None:
        self.loop.failed(request.step)


def camera_frame(type_: str, msg: Any) -> Frame:
    """A camera's message as the frame it carries (checked: sizes, encoding), not decoded:
    the policy decodes it, wherever it runs."""
    if type_ == "sensor_msgs/CompressedImage":
        return compressed_frame(bytes(msg.data), str(msg.format))
    return raw_frame(bytes(msg.data), str(msg.encoding), int(msg.width), int(msg.height),
                     int(msg.step))


def _state_size(settings: ControlSettings) -> int:
    """The state's length as the parts say, or -1 when a part does not say (checked on the
    first observation against what arrives)."""
    sizes = [part.size if part.type == "std_msgs/Float64MultiArray" else
             len(part.joints) * len(part.fields) if part.joints is not None else None
             for part in settings.state]
    return -1 if None in sizes else sum(s or 0 for s in sizes)


def open_source(route: str, config: Any, submit: Submit, on_end: OnEnd,
                context: ComponentContext) -> Source:
    return ControlSource(route, config.control, submit, context)


COMPONENT = SourceKind("control", ControlInput, lambda config: "state", open_source,
                       latest=lambda config: True, ros=True, acts=True,
                       rate_hz=lambda config: config.control.rate_hz,
                       more_fields=lambda config: frozenset(
                           {"step", "capture_time_ns", "committed", "images"}), rank=6)
