"""A control input: a route that ticks at the policy's rate instead of once per message. The
observation assembled from the newest state messages (`observation`), a request to the
route's policy (`call: {method: Act}`) when the queue runs short (`loop`), one action a tick
through the target's policy (`target`: bounds, rate, deadman), the safe action when nothing
is queued; ticked on its own clock or by the robot's state (`ticks`).

Its requests go to the route as items (`Asked`) and the route tells each what became of it
(oricf.gateway.items.Asker): the answer's chunk is queued, a failure lets the loop ask again.
It reads and writes no topic itself: whoever opens it subscribes its `takers` and gives it
the target's publisher (oricf.gateway.sources.control, on the ROS node's topics).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from oricf.gateway.control.loop import ControlLoop, Request
from oricf.gateway.control.observation import MissingState, Observation
from oricf.gateway.control.parts import camera_frame
from oricf.gateway.control.queue import ActionQueue, BadChunk, Origin
from oricf.gateway.control.settings import ControlSettings
from oricf.gateway.control.target import ActionTarget, Publish
from oricf.gateway.control.ticks import TICKS, Ticks
from oricf.gateway.items import Asker, Submit
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import Record

log = logging.getLogger(__name__)

Take = Callable[[Any], None]  # called with each message of a topic


class Asked(Asker):
    """One request as the route's item; the route tells it its answer or its failure, on
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
                "images": request.images}

    def answered(self, record: Record) -> None:
        self.source.answered(self.request, record)
        self._spent()

    def fail(self, message: str) -> None:
        self.source.failed(self.request, message)
        self._spent()

    def on_drop(self, reason: str) -> None:
        self.source.failed(self.request, reason)

    def _spent(self) -> None:
        if self._started_cpu_ns:
            self.source.loop.counts.request_cpu_ns += time.thread_time_ns() - self._started_cpu_ns


class ControlSource:
    def __init__(self, route: str, settings: ControlSettings, submit: Submit,
                 publish: Publish) -> None:
        """`submit` hands the route a request; `publish` sends a message to the target's
        topic."""
        self.route = route
        self.settings = settings
        queue = ActionQueue(settings.action_dim, settings.late, settings.merge,
                            horizon=settings.ahead_steps())
        self.loop = ControlLoop(queue, settings.safe(), settings.request_at,
                                settings.deadline_steps, settings.hold_steps,
                                settings.send_committed, settings.max_in_flight)
        self.observation = Observation(settings.state, settings.state_size(),
                                       settings.max_age_ms, settings.images, camera_frame)
        self.target = ActionTarget(settings.target, publish, settings.safe())
        self.ticks: Ticks = TICKS[settings.tick](self, settings.rate_hz, f"control-{route}")
        self._submit = submit
        self._throttle = ThrottledLog(log)
        self._acted = -1

    def takers(self) -> list[tuple[str, str, Take]]:
        """(topic, message type, what takes its messages) of each state part and camera."""
        states = [(part.topic, part.type, self._taker(index, "state"))
                  for index, part in enumerate(self.settings.state)]
        return states + [(camera.topic, camera.type, self._taker(index, "image"))
                         for index, camera in enumerate(self.settings.images)]

    def _taker(self, index: int, kind: str) -> Take:
        take = self.observation.take if kind == "state" else self.observation.take_image
        ticks = kind == "state" and index == 0

        def taken(msg: Any) -> None:
            cpu = time.thread_time_ns()
            try:
                take(index, msg)
            except MissingState as exc:
                self._throttle.warning(f"{kind}:{index}", "route %s: %s refused: %s",
                                       self.route, kind, exc)
            self.loop.counts.tick_cpu_ns += time.thread_time_ns() - cpu
            if ticks:
                self.ticks.on_state()
        return taken

    def start(self) -> None:
        log.info("route %s: control loop at %g Hz (ticked by its %s) -> %s (%s)", self.route,
                 self.settings.rate_hz, self.settings.tick, self.settings.target.topic,
                 self.settings.target.type)
        self.ticks.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stops ticking; the target's last message is the safe action."""
        self.ticks.stop(timeout)  # no state or answer acts after this
        self.loop.stop()
        self.target.close()

    def ask(self, step: int) -> bool:
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

    def act(self, step: int) -> None:
        tick = self.loop.act(step, time.monotonic_ns())
        self._acted = step
        self.target.send(tick.action)

    def restarted(self, silent_ns: int) -> None:
        self._throttle.warning("restart", "route %s: the robot's state came back after "
                               "%.0f ms: the actions queued before it dropped", self.route,
                               silent_ns / 1e6)

    def answered(self, request: Request, record: Record) -> None:
        queued = self._queue_answer(request, record)
        self.ticks.on_answer(request.step)
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
