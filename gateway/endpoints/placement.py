"""Placement by latency budget: calls go to the preferred place (an endpoint's `address` or
its `fallback`) while it answers within the budget, and to the other one while it does not,
not only when it fails.

    endpoints:
      detector:
        address: edge.local:50051
        fallback: 127.0.0.1:50051
        placement: {latency_budget_ms: 150, prefer: address, window: 20, hysteresis_s: 10}

The gateway keeps the latencies of the last `window` real calls to the preferred place; when
their 90th percentile passes the budget, calls move to the other. While there, a light
probe (the readiness check) measures the preferred place's round trip every
`probe_interval_s`; its estimate is the probes' 90th percentile plus what a call cost beyond
a probe while it was within budget (the service's own time, the frame's upload). Calls
return once that estimate has stayed within the budget for `hysteresis_s`.

With `onboard` (which of the two runs on the robot), the robot has a say too: while its CPU
use (all cores, from /proc/stat, over each probe interval) is over `onboard_cpu_ceiling`,
or its battery (sensor_msgs/BatteryState on `battery_topic`, read by the ROS node) is under
`battery_low`, calls leave the onboard place and do not move back to it, over budget or
not; the robot comes first. Every decision is logged with its reason and counted
(oricf_gateway_endpoint_placements{reason}).
"""

from __future__ import annotations

import logging
import math
import statistics
import threading
import time
from collections import Counter, deque
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from oricf.config import Schema
from oricf.stats import p90

log = logging.getLogger(__name__)

MIN_SAMPLES = 5  # a decision needs at least this many latencies
Place = Literal["address", "fallback"]
PROC_STAT = Path("/proc/stat")
# Why calls moved, as the metrics count it.
REASONS = ("over_budget", "back_within_budget", "failed", "cpu_over_ceiling", "battery_low",
           "hedged")


class PlacementConfig(Schema):
    latency_budget_ms: float | None = Field(None, gt=0, le=600_000,
                                            description="a call to the preferred place should "
                                                        "take at most this")
    latency_budget_steps: int | None = Field(
        None, ge=1, le=10_000, description="the budget in control steps of the control input "
                                           "that calls the endpoint (instead of ms)")
    hedge: bool = Field(False, description="a call the preferred place has not answered "
                                           "within the budget goes to the other place, whose "
                                           "answer is taken")
    prefer: Place = Field("address", description="where calls go while it answers within the "
                                                 "budget: address or fallback")
    window: int = Field(20, ge=MIN_SAMPLES, le=10_000,
                        description="latencies (real calls, probes) the percentile is taken over")
    hysteresis_s: float = Field(10.0, ge=0, le=3600,
                                description="the preferred place must stay within budget this "
                                            "long before calls return to it")
    probe_interval_s: float = Field(1.0, gt=0, le=60,
                                    description="how often the preferred place is probed")
    onboard: Place | None = Field(None, description="which of address and fallback runs on "
                                                    "the robot (for onboard_cpu_ceiling, "
                                                    "battery_topic)")
    onboard_cpu_ceiling: float | None = Field(
        None, gt=0, lt=1, description="robot CPU use (0-1, all cores) above which calls "
                                      "leave the onboard place and do not return to it")
    battery_topic: str | None = Field(
        None, min_length=1, description="a sensor_msgs/BatteryState topic: under battery_low "
                                        "calls leave the onboard place (needs ROS)")
    battery_low: float = Field(0.2, gt=0, lt=1, description="battery_topic: the charge "
                                                            "(its percentage, 0-1) under which")

    @model_validator(mode="after")
    def _one_budget(self) -> PlacementConfig:
        if (self.latency_budget_ms is None) == (self.latency_budget_steps is None):
            raise ValueError("give exactly one of latency_budget_ms or latency_budget_steps")
        return self

    @model_validator(mode="after")
    def _robot_inputs_need_onboard(self) -> PlacementConfig:
        for key in ("onboard_cpu_ceiling", "battery_topic"):
            if getattr(self, key) is not None and self.onboard is None:
                raise ValueError(f"{key}: needs `onboard` (address or fallback: which of the "
                                 f"two runs on the robot)")
        return self

    @property
    def other(self) -> Place:
        return "fallback" if self.prefer == "address" else "address"


class RobotCpu:
    """The share of all cores' time spent busy between two readings of /proc/stat."""

    def __init__(self) -> None:
        self._last = self._ticks()

    @staticmethod
    def _ticks() -> tuple[int, int]:
        """(busy, total) clock ticks since boot; idle and iowait count as not busy."""
        # user nice system idle iowait irq softirq steal; guest time is already in user's
        fields = [int(v) for v in PROC_STAT.read_text().split("\n", 1)[0].split()[1:9]]
        idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
        return sum(fields) - idle, sum(fields)

    def use(self) -> float:
        (busy, total), (last_busy, last_total) = self._ticks(), self._last
        self._last = busy, total
        return (busy - last_busy) / (total - last_total) if total > last_total else 0.0


class Placement:
    """Where calls go (the preferred place or the other) by the preferred place's observed
    latency and, with a ceiling, the robot's CPU use."""

    def __init__(self, endpoint: str, config: PlacementConfig,
                 step_s: float | None = None) -> None:
        """`step_s`: the control period of the loop that calls the endpoint, for a budget
        in steps."""
        self.endpoint = endpoint
        self.config = config
        if config.latency_budget_steps is not None:
            if step_s is None:
                raise ValueError("latency_budget_steps needs the control rate")
            self.budget_ms = config.latency_budget_steps * step_s * 1e3
            self.budget_text = (f"{self.budget_ms:.1f} ms ({config.latency_budget_steps} "
                                f"steps at {1 / step_s:g} Hz)")
        else:
            assert config.latency_budget_ms is not None
            self.budget_ms = config.latency_budget_ms
            self.budget_text = f"{self.budget_ms:.0f} ms"
        self.moved = False  # calls go to the other place
        self.decisions: Counter[str] = Counter()  # reason -> count
        self.robot_cpu: float | None = None  # the last reading, with a ceiling
        self.battery: float | None = None  # the last charge read, 0-1, with a battery topic
        self._calls: deque[float] = deque(maxlen=config.window)   # real calls, ms
        self._probes: deque[float] = deque(maxlen=config.window)  # probes, ms
        self._beyond_probe_ms = 0.0  # what a call cost beyond a probe, within budget
        self._within_since: float | None = None
        self._lock = threading.Lock()

    @property
    def place(self) -> Place:
        """Where calls go now: address or fallback."""
        return self.config.other if self.moved else self.config.prefer

    def _robot_bars(self) -> tuple[str, str] | None:
        """(reason, why) while the robot keeps calls off its onboard place."""
        config = self.config
        ceiling, low = config.onboard_cpu_ceiling, config.battery_low
        if ceiling is not None and self.robot_cpu is not None and self.robot_cpu > ceiling:
            return "cpu_over_ceiling", (f"robot CPU {self.robot_cpu:.0%} over the ceiling of "
                                        f"{ceiling:.0%}")
        if self.battery is not None and self.battery < low:
            return "battery_low", f"battery at {self.battery:.0%}, under {low:.0%}"
        return None

    def _bars(self, place: Place) -> bool:
        """Whether the robot keeps calls from moving to `place` now."""
        return place == self.config.onboard and self._robot_bars() is not None

    def _leave_onboard(self) -> None:
        """Moves calls off the onboard place while the robot bars it."""
        barred = self._robot_bars()
        if barred is not None and self.place == self.config.onboard:
            self._move(not self.moved, barred[1], barred[0])

    def call_took(self, seconds: float) -> None:
        """A real call to the preferred place answered after this long."""
        ms = seconds * 1e3
        with self._lock:
            self._calls.append(ms)
            if len(self._calls) < MIN_SAMPLES:
                return
            observed = p90(self._calls)
            if observed <= self.budget_ms:
                if self._probes:
                    self._beyond_probe_ms = max(
                        0.0, statistics.median(self._calls) - statistics.median(self._probes))
                return
            if self.moved or self._bars(self.config.other):
                return
            self._move(True, f"p90 {observed:.1f} ms over the budget of {self.budget_text}",
                       "over_budget")

    def hedged(self, code: str) -> None:
        """A call the preferred place did not answer within the budget (or failed) was
        answered by the other place."""
        with self._lock:
            self.decisions["hedged"] += 1
            count = self.decisions["hedged"]
        if count == 1 or count % 100 == 0:  # every switch counted; the log kept readable
            log.warning("endpoint %s: a call not answered within the budget of %s by its %s "
                        "(%s) was answered by its %s (%d so far)", self.endpoint,
                        self.budget_text, self.config.prefer, code, self.config.other, count)

    def failed(self, place: Place, code: str) -> bool:
        """A call to `place` failed (unavailable, deadline): if calls go there, they move to
        the other place at once (back to the preferred one later through the probes);
        whether they moved."""
        with self._lock:
            if place != self.place:
                return False
            self._move(not self.moved, f"a call to its {place} failed ({code})", "failed")
            return True

    def probe_took(self, seconds: float | None) -> None:
        """A probe of the preferred place answered after this long (None: it did not)."""
        with self._lock:
            if seconds is None:
                self._probes.clear()
                self._within_since = None
                return
            self._probes.append(seconds * 1e3)
            if not self.moved or len(self._probes) < MIN_SAMPLES:
                return
            estimate = p90(self._probes) + self._beyond_probe_ms
            now = time.monotonic()
            if estimate > self.budget_ms or self._bars(self.config.prefer):
                self._within_since = None
                return
            self._within_since = self._within_since or now
            if now - self._within_since >= self.config.hysteresis_s:
                self._move(False, f"estimated p90 {estimate:.0f} ms within the budget for "
                                  f"{now - self._within_since:.0f} s", "back_within_budget")

    def cpu_read(self, use: float) -> None:
        """The robot's CPU use over the last probe interval (0-1): above the ceiling, calls
        leave the onboard place."""
        with self._lock:
            self.robot_cpu = use
            self._leave_onboard()

    def battery_read(self, charge: float) -> None:
        """The robot's battery charge (0-1; NaN, unknown, is ignored): under battery_low,
        calls leave the onboard place."""
        if math.isnan(charge):
            return
        with self._lock:
            self.battery = charge
            self._leave_onboard()

    def _move(self, away: bool, why: str, reason: str) -> None:
        self.moved = away
        self.decisions[reason] += 1
        self._calls.clear()
        self._probes.clear()
        self._within_since = None
        log.warning("endpoint %s: calls move to its %s: %s", self.endpoint, self.place, why)
