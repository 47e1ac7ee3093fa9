"""What a control loop does at each tick, apart from its clock and its transport: decide
whether to ask the policy for the next chunk with the observation just captured (`ask`),
then take the action for the step from the queue, or the safe action (`act`). A policy that
answers at once (onboard) is asked before the action is taken, so its answer is used on the
same tick. The gateway's control input (oricf.gateway.control.source) runs it
on the robot's clock; `oricf bench control` runs it on a simulator's steps.

    request_at   ask for the next chunk when this many actions (or fewer) are queued from
                 the current step on: 0 asks only once the queue is dry (so a policy of one
                 action per answer is asked at every tick)
    max_in_flight  requests pending at once (more than 1 pipelines a policy of one action
                 per answer over a link slower than a tick)
    deadline     steps a request may stay unanswered before the loop asks again (the edge
                 stalled, or the answer was lost); a late answer is still taken, its late
                 actions skipped
    hold_steps   ticks the last action is repeated when nothing is queued, before the safe
                 action (0: the safe action at once)

A chunk is refused when it answers an observation the loop did not ask for (or asked before
a restart), one older than one already answered, or one answered already (an answer that
arrives late, or twice, moves nothing). The observation an answer is for is the one its
request sent, which the caller knows: a step the answer names for itself is only checked
against it. An asked observation is kept for a late answer as long as an action answering it
could still be within the queue's horizon.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from oricf.gateway.control.queue import ActionQueue, BadChunk, Origin
from oricf.metrics import LatencyHistogram
from oricf.stats import percentile

AGES_KEPT = 10_000


@dataclass(frozen=True)
class Request:
    """An observation to send to the policy."""

    step: int
    state: np.ndarray
    capture_time_ns: int
    committed: tuple[int, np.ndarray] | None   # (first step, actions) already queued
    # Each camera's image, by its name, as the transport carries it (the gateway: frames as
    # they came off the topic; the bench: arrays). None: a policy without cameras.
    images: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class Tick:
    step: int
    action: np.ndarray
    safe: bool                    # the safe action: nothing queued, nothing to hold
    origin: Origin | None         # the observation behind the action (None: safe or held)


@dataclass
class LoopCounts:
    safe_ticks: int = 0           # ticks that sent the safe action
    held_ticks: int = 0           # ticks that repeated the last action
    requests: int = 0
    answers: int = 0
    expired: int = 0              # requests left unanswered past the deadline
    refused_chunks: int = 0       # answers to an observation not asked, or older than one
                                  # answered, or a chunk the queue refused
    failed: int = 0               # calls that failed (the route told the loop)
    missing_state: int = 0        # ticks without an observation (stale, missing, bad)
    late_ticks: int = 0           # ticks that started after their time (steps skipped)
    restarts: int = 0             # times the queue was dropped as stale (restart)
    # CPU the loop's own work took, in nanoseconds of its threads' time, kept by whoever
    # runs the loop: the ticks (taking the state and images as they come, assembling the
    # observation, merging, publishing) and the requests (the call's message, the call on
    # its thread, taking the answer).
    tick_cpu_ns: int = 0
    request_cpu_ns: int = 0


@dataclass
class Ages:
    """How old the observation behind each action was when the action went out."""

    seconds: LatencyHistogram = field(default_factory=LatencyHistogram)
    steps: deque[int] = field(default_factory=lambda: deque(maxlen=AGES_KEPT))  # the last

    def percentile(self, q: float) -> float | None:
        """The q-th percentile of the ages in steps kept (None before any)."""
        return percentile(self.steps, q) if self.steps else None


class ControlLoop:
    """Thread-safe: ticks on the loop's thread, answers from the thread that called."""

    def __init__(self, queue: ActionQueue, safe_action: np.ndarray, request_at: int,
                 deadline: int, hold_steps: int = 0, send_committed: bool = False,
                 max_in_flight: int = 1) -> None:
        self.queue = queue
        self.safe_action = np.asarray(safe_action, np.float64)
        self.request_at = request_at
        self.deadline = deadline
        self.hold_steps = hold_steps
        self.send_committed = send_committed
        self.max_in_flight = max_in_flight
        self.counts = LoopCounts()
        self.ages = Ages()
        self._lock = threading.Lock()
        self._in_flight: set[int] = set()        # the observation steps asked, unanswered
        # ... and those given up past the deadline, whose answer may still come; none older
        # than the newest answered
        self._asked: set[int] = set()
        self._last: np.ndarray | None = None
        self._dry = 0                             # ticks since the queue gave an action

    def ask(self, step: int, state: np.ndarray, now_ns: int = 0,
            images: Mapping[str, Any] | None = None) -> Request | None:
        """Before the action for `step` is taken: the request to send for the observation
        captured at `step`, if the queue is short enough and no request is pending (or
        fewer than `max_in_flight`)."""
        with self._lock:
            expired = {asked for asked in self._in_flight if step - asked > self.deadline}
            self._in_flight -= expired
            self.counts.expired += len(expired)
            if (len(self._in_flight) >= self.max_in_flight
                    or self.queue.remaining(step) > self.request_at):
                return None
            # An answer to an observation past the horizon has no action left to play.
            self._asked = {asked for asked in self._asked
                           if step - asked <= self.queue.horizon}
            self._in_flight.add(step)
            self._asked.add(step)
            self.counts.requests += 1
        committed = self.queue.committed(step) if self.send_committed else None
        return Request(step, state, now_ns, committed, images)

    def act(self, step: int, now_ns: int | None = None) -> Tick:
        """The action for `step`: the queue's, else the last one held, else the safe one;
        the age of its observation is kept (in time too, given the clock's `now_ns`)."""
        action = self.queue.take(step)
        origin = self.queue.last_origin
        if origin is not None:
            self.ages.steps.append(step - origin.step)
            if now_ns is not None:
                self.ages.seconds.observe((now_ns - origin.capture_time_ns) / 1e9)
        safe = False
        with self._lock:
            if action is not None:
                self._dry = 0
            else:
                self._dry += 1
                if self._last is not None and self._dry <= self.hold_steps:
                    action = self._last
                    self.counts.held_ticks += 1
                else:
                    action, safe = self.safe_action, True
                    self.counts.safe_ticks += 1
            self._last = None if safe else action
        return Tick(step, action, safe, origin)

    def deliver(self, actions: np.ndarray, start_step: int, origin: Origin, now: int) -> int:
        """A chunk answering the observation of `origin` (the step of the request it
        answers), arriving after the action for `now` was taken (`step - 1` when it arrives
        before the action for `step`); returns how many of its actions were queued (0 if
        refused). Raises queue.BadChunk for a malformed chunk."""
        with self._lock:
            self._in_flight.discard(origin.step)
            if origin.step not in self._asked:  # not asked, answered, or older than answered
                self.counts.refused_chunks += 1
                return 0
        try:
            queued = self.queue.put(actions, start_step, now, origin)
        except BadChunk:
            self.refuse(origin.step)
            raise
        with self._lock:
            self._asked = {asked for asked in self._asked if asked > origin.step}
            self.counts.answers += 1
        return queued

    def refuse(self, observation_step: int) -> None:
        """The answer to this observation's request is refused (a malformed chunk, or one
        that says it answers another observation): the next tick may ask again."""
        with self._lock:
            self._in_flight.discard(observation_step)
            self._asked.discard(observation_step)
            self.counts.refused_chunks += 1

    def failed(self, observation_step: int) -> None:
        """The request for this observation failed: the next tick may ask again."""
        with self._lock:
            self._in_flight.discard(observation_step)
            self._asked.discard(observation_step)
            self.counts.failed += 1

    def stop(self) -> None:
        """Nothing queued is played any more, and no answer still on its way is taken; the
        next tick sends the safe action."""
        self.queue.clear()
        with self._lock:
            self._last = None
            self._in_flight.clear()
            self._asked.clear()

    def restart(self) -> None:
        """What was queued, held or asked until now is stale (the robot was silent and the
        loop did not tick): all of it dropped, and an answer to an observation asked before
        that still comes is refused."""
        self.stop()
        with self._lock:
            self.counts.restarts += 1
