"""When a control loop ticks (`tick:` of its settings), one entry each in `TICKS`:

    clock  a thread ticks on an absolute schedule at `rate_hz`, so a late tick does not shift
           the ones after it (steps are time); a tick that starts after the next one's time
           skips the steps passed
    state  each message of the first state part is a step (the robot's clock), and its
           action goes out as soon as it is known: at once when queued, else when the answer
           to that state comes (or, if the next state comes first, then: held or safe)

A tick mode drives the loop through `Steps` (oricf.gateway.control.source.ControlSource).
"""

from __future__ import annotations

import threading
import time
from typing import Protocol

from oricf.gateway.control.loop import ControlLoop
from oricf.gateway.control.observation import Observation


class Steps(Protocol):
    """What a tick mode drives: a control input's loop, asked and acted on step by step."""

    loop: ControlLoop
    observation: Observation

    def ask(self, step: int) -> bool:
        """Sends the observation to the policy if the loop asks for it now; whether it did."""

    def act(self, step: int) -> None:
        """The action for `step` to the target."""

    def restarted(self, silent_ns: int) -> None:
        """The robot was silent this long: the loop dropped what it had (say so)."""


class Ticks(Protocol):
    def start(self) -> None: ...

    def on_state(self) -> None:
        """A message of the first state part came (taken into the observation)."""

    def on_answer(self, step: int) -> None:
        """The answer to the observation of `step` was queued."""

    def stop(self, timeout: float) -> None:
        """No tick, state or answer acts once this returns."""


class ClockTicks:
    def __init__(self, steps: Steps, rate_hz: float, name: str) -> None:
        self._steps = steps
        self._period = 1.0 / rate_hz
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name=name)

    def start(self) -> None:
        self._thread.start()

    def on_state(self) -> None:
        pass

    def on_answer(self, step: int) -> None:
        pass

    def stop(self, timeout: float) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self) -> None:
        counts = self._steps.loop.counts
        started = time.monotonic()
        step = 0
        while not self._stop.is_set():
            cpu = time.thread_time_ns()
            self._steps.ask(step)
            self._steps.act(step)
            counts.tick_cpu_ns += time.thread_time_ns() - cpu
            step += 1
            wait = started + step * self._period - time.monotonic()
            if wait < 0:  # behind: the steps whose time passed are not played
                missed = int(-wait / self._period)
                counts.late_ticks += 1
                step += missed
                wait += missed * self._period
            self._stop.wait(max(0.0, wait))


class StateTicks:
    """States and answers one at a time (a lock): each acts on the newest step alone."""

    def __init__(self, steps: Steps, rate_hz: float, name: str) -> None:
        self._steps = steps
        self._step = -1                     # the newest state's step
        self._pending: int | None = None    # a step whose action awaits its answer
        self._last_state_ns = 0             # when the newest state came
        self._stopped = False
        self._lock = threading.Lock()

    def start(self) -> None:
        pass

    def stop(self, timeout: float) -> None:
        with self._lock:  # a state or answer acting now finishes first
            self._stopped = True

    def on_state(self) -> None:
        """A new step. The step before it, if still waiting for its answer, is acted on now
        (held or safe); this one at once when an action is queued for it, else when its
        answer comes."""
        cpu = time.thread_time_ns()
        try:
            self._step_on_state()
        finally:
            self._steps.loop.counts.tick_cpu_ns += time.thread_time_ns() - cpu

    def _step_on_state(self) -> None:
        steps, now = self._steps, time.monotonic_ns()
        with self._lock:
            if self._stopped:
                return
            silent_ns = now - self._last_state_ns
            self._last_state_ns = now
            if self._step >= 0 and silent_ns > steps.observation.max_age_ns:
                # The loop did not tick while the robot was silent: what it queued, held or
                # asked before was planned for a robot that has moved on since.
                self._pending = None
                steps.loop.restart()
                steps.restarted(silent_ns)
            if self._pending is not None:
                steps.act(self._pending)
                self._pending = None
            self._step += 1
            asked = steps.ask(self._step)
            if asked and steps.loop.queue.remaining(self._step) == 0:
                self._pending = self._step
            else:
                steps.act(self._step)

    def on_answer(self, step: int) -> None:
        with self._lock:
            if self._pending == step and not self._stopped:
                self._steps.act(step)  # the action of the state this answers, at once
                self._pending = None


TICKS: dict[str, type[ClockTicks] | type[StateTicks]] = {"clock": ClockTicks,
                                                         "state": StateTicks}
