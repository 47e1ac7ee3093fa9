"""Placement by latency budget: calls go to an endpoint's primary (the preferred place,
e.g. the edge) while it answers within the budget, and to its fallback (e.g. onboard) while
it does not, not only when it fails.

    endpoints:
      detector:
        address: edge.local:50051              # preferred
        fallback: 127.0.0.1:50051
        placement: {latency_budget_ms: 150, window: 20, hysteresis_s: 10}

The gateway keeps the latencies of the last `window` real calls to the primary; when their
90th percentile passes the budget, calls move to the fallback. While there, a light probe
(the readiness check) measures the primary's round trip every `probe_interval_s`; its
estimate is the probes' 90th percentile plus what a call cost beyond a probe while the
primary was within budget (the service's own time, the frame's upload). Calls return once
that estimate has stayed within the budget for `hysteresis_s`. Every decision is logged
with its reason and counted (oricf_gateway_endpoint_placements{reason}).
"""

from __future__ import annotations

import logging
import statistics
import threading
import time
from collections import Counter, deque

from pydantic import Field

from oricf.config import Schema

log = logging.getLogger(__name__)

PERCENTILE = 90
MIN_SAMPLES = 5  # a decision needs at least this many latencies


class PlacementConfig(Schema):
    latency_budget_ms: float = Field(gt=0, le=600_000,
                                     description="a call to the primary should take at most this")
    window: int = Field(20, ge=MIN_SAMPLES, le=10_000,
                        description="latencies (real calls, probes) the percentile is taken over")
    hysteresis_s: float = Field(10.0, ge=0, le=3600,
                                description="the primary must stay within budget this long "
                                            "before calls return to it")
    probe_interval_s: float = Field(1.0, gt=0, le=60,
                                    description="how often the primary is probed")


def p90(values: deque[float]) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(len(ordered) * PERCENTILE / 100))]


class Placement:
    """Where calls go (primary or fallback) by the primary's observed latency."""

    def __init__(self, endpoint: str, config: PlacementConfig) -> None:
        self.endpoint = endpoint
        self.config = config
        self.moved = False
        self.decisions: Counter[str] = Counter()  # reason -> count
        self._calls: deque[float] = deque(maxlen=config.window)   # real calls, ms
        self._probes: deque[float] = deque(maxlen=config.window)  # probes, ms
        self._beyond_probe_ms = 0.0  # what a call cost beyond a probe, within budget
        self._within_since: float | None = None
        self._lock = threading.Lock()

    def call_took(self, seconds: float) -> None:
        """A real call to the primary answered after this long."""
        ms = seconds * 1e3
        with self._lock:
            self._calls.append(ms)
            if len(self._calls) < MIN_SAMPLES:
                return
            observed = p90(self._calls)
            budget = self.config.latency_budget_ms
            if observed <= budget:
                if self._probes:
                    self._beyond_probe_ms = max(
                        0.0, statistics.median(self._calls) - statistics.median(self._probes))
                return
            if self.moved:
                return
            self._move(True, f"p90 {observed:.0f} ms over the budget of {budget:.0f} ms",
                       "over_budget")

    def probe_took(self, seconds: float | None) -> None:
        """A probe of the primary answered after this long (None: it did not)."""
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
            if estimate > self.config.latency_budget_ms:
                self._within_since = None
                return
            self._within_since = self._within_since or now
            if now - self._within_since >= self.config.hysteresis_s:
                self._move(False, f"estimated p90 {estimate:.0f} ms within the budget for "
                                  f"{now - self._within_since:.0f} s", "back_within_budget")

    def _move(self, away: bool, why: str, reason: str) -> None:
        self.moved = away
        self.decisions[reason] += 1
        self._calls.clear()
        self._probes.clear()
        self._within_since = None
        log.warning("endpoint %s: calls move to the %s: %s", self.endpoint,
                    "fallback" if away else "primary", why)
