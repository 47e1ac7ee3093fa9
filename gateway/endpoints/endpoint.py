"""An endpoint: the server a route calls, with a deadline on every call, retries while the
server says it is busy, and failover to a fallback (see the package's docstring)."""

from __future__ import annotations

import itertools
import logging
import random
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import grpc

from oricf.gateway.endpoints.config import EndpointConfig, TargetConfig
from oricf.gateway.endpoints.grpc import GrpcTarget, Service, refused_as_too_large
from oricf.gateway.endpoints.placement import Placement, RobotCpu

log = logging.getLogger(__name__)

T = TypeVar("T")
# A call on one target, with the time left of its deadline (s).
Work = Callable[[Any, float], T]

FAILOVER_CODES = frozenset({grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED})
PROBE_TIMEOUT_S = 1.0


def _pushback_ms(exc: grpc.RpcError) -> float:
    """The wait the server asked for (gRPC's grpc-retry-pushback-ms; HTTP's Retry-After),
    0 if none."""
    metadata = dict(exc.trailing_metadata() or ())  # type: ignore[attr-defined]
    try:
        return max(0.0, float(metadata.get("grpc-retry-pushback-ms", 0)))
    except (TypeError, ValueError):
        return 0.0


def open_target(config: TargetConfig, service: Service, reply_bytes: int | None = None
                ) -> Any:
    if config.protocol == "openai":
        from oricf.gateway.endpoints.openai import OpenAITarget  # the openai client, if used

        return OpenAITarget(config)
    return GrpcTarget(config, service, reply_bytes)


class Endpoint:
    """A server the routes call: `service.stub` makes a gRPC target's client on its
    channel, `service.ready` asks whether a gRPC server is ready (the probe that ends a
    failover); an OpenAI-compatible target has its own client and probe."""

    def __init__(self, name: str, config: EndpointConfig, service: Service,
                 step_s: float | None = None, reply_bytes: int | None = None) -> None:
        """`step_s`: the control period of the loop that calls it (a budget in steps);
        `reply_bytes`: the largest answer its gRPC targets take (a larger one is refused as
        it arrives, before it is read into memory)."""
        self.name = name
        self.config = config
        targets = config.targets
        self.primary = open_target(targets["address"], service, reply_bytes)
        self.fallback = (open_target(targets["fallback"], service, reply_bytes)
                         if "fallback" in targets else None)
        self.failovers = 0
        self.recoveries = 0
        self.retries = 0
        self.answered = {"primary": 0, "fallback": 0}  # calls answered, by target
        self._on_fallback = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._probe: threading.Thread | None = None
        self.placement = (Placement(name, config.placement, step_s)
                          if config.placement is not None else None)
        if self.placement is not None:
            threading.Thread(target=self._probe_placement, daemon=True,
                             name=f"placement-{name}").start()

    @property
    def deadline_s(self) -> float:
        return self.config.deadline_ms / 1000.0

    @property
    def active(self) -> Any:
        """The target calls go to now: the fallback while the primary has failed, else where
        the placement (if any) puts them."""
        with self._lock:
            if self._on_fallback and self.fallback is not None:
                return self.fallback
        return self.target(self.placement.place) if self.placement is not None else self.primary

    def target(self, place: str) -> Any:
        """The target of a place: address (the primary) or fallback."""
        return self.fallback if place == "fallback" and self.fallback else self.primary

    @property
    def preferred(self) -> Any:
        """Where the placement prefers calls to go (the primary without a placement)."""
        return self.target(self.placement.config.prefer) if self.placement else self.primary

    def call(self, rpc: str, request: Any) -> Any:
        """Calls a gRPC rpc on the active target (a gRPC-only endpoint)."""
        return self.run({"grpc": lambda target, timeout: target.invoke(rpc, request, timeout)})

    def run(self, work: Mapping[str, Work[T]]) -> T:
        """Runs the work for the active target's protocol; fails over once on UNAVAILABLE or
        DEADLINE_EXCEEDED, and runs the fallback's work there."""
        target = self.active
        if self._hedges(target):
            return self._hedged(target, work)
        try:
            return self._attempts(target, work)
        except grpc.RpcError as exc:
            if self.fallback is None or exc.code() not in FAILOVER_CODES:
                raise
            if target is self.primary:
                self._fail_over(exc)
                return self._attempts(self.fallback, work)
            # The fallback failed: it was where the placement sent calls (preferred, or
            # moved there), so the placement moves them to the primary.
            if self.placement is None or not self.placement.failed("fallback", exc.code().name):
                raise
            return self._attempts(self.primary, work)

    def _hedges(self, target: Any) -> bool:
        placement = self.placement
        return (placement is not None and placement.config.hedge and self.fallback is not None
                and target is self.preferred)

    def _hedged(self, target: Any, work: Mapping[str, Work[T]]) -> T:
        """The preferred place given the budget only; past it, or failed, the other place
        answers (its answer taken, the call counted as hedged)."""
        assert self.placement is not None
        budget_s = self.placement.budget_ms / 1e3
        try:
            return self._attempts(target, work, min(budget_s, self.deadline_s))
        except grpc.RpcError as exc:
            if exc.code() not in FAILOVER_CODES:
                raise
            if exc.code() == grpc.StatusCode.DEADLINE_EXCEEDED:
                self.placement.call_took(budget_s)  # at least: its percentile sees it
            self.placement.hedged(exc.code().name)
        other = self.target(self.placement.config.other)
        return self._attempts(other, work)

    def _attempts(self, target: Any, work: Mapping[str, Work[T]],
                  deadline_s: float | None = None) -> T:
        """One target, its deadline, and retries while it refuses the call as busy."""
        deadline = time.monotonic() + (deadline_s or self.deadline_s)
        for attempt in itertools.count(1):
            started = time.monotonic()
            try:
                result = work[target.protocol](target, max(deadline - started, 0.001))
            except grpc.RpcError as exc:
                wait = self._retry_wait(exc, attempt, deadline - time.monotonic())
                if wait is None:
                    raise
                with self._lock:  # routes call from threads of their own
                    self.retries += 1
                log.debug("endpoint %s: %s busy, retry %d in %.0f ms", self.name,
                          target.address, attempt, wait * 1000)
                time.sleep(wait)
                continue
            if self.placement is not None and target is self.preferred:
                self.placement.call_took(time.monotonic() - started)
            with self._lock:
                self.answered["primary" if target is self.primary else "fallback"] += 1
            return result
        raise AssertionError("unreachable")

    def _retry_wait(self, exc: grpc.RpcError, attempt: int, remaining: float) -> float | None:
        """Seconds to wait before retrying a refused call, or None to give up. Busy is
        retried; unavailable only when the server said for how long (HTTP 503 with
        Retry-After), else the endpoint fails over at once."""
        retry, pushback = self.config.retry, _pushback_ms(exc)
        busy = exc.code() == grpc.StatusCode.RESOURCE_EXHAUSTED and not refused_as_too_large(exc)
        paused = exc.code() == grpc.StatusCode.UNAVAILABLE and pushback > 0
        if not (busy or paused) or attempt > retry.attempts:
            return None
        backoff = min(retry.max_backoff_ms, retry.initial_backoff_ms * 2 ** (attempt - 1))
        wait_ms = max(backoff * random.uniform(0.5, 1.5), pushback)
        return wait_ms / 1000 if wait_ms / 1000 < remaining else None

    def _fail_over(self, exc: grpc.RpcError) -> None:
        assert self.fallback is not None
        with self._lock:
            if self._on_fallback:
                return
            self._on_fallback = True
            self.failovers += 1
            # Started and cleared under the lock that flips the state: never two probes,
            # never on the fallback without one.
            self._probe = threading.Thread(target=self._probe_primary, daemon=True,
                                           name=f"probe-{self.name}")
            self._probe.start()
        log.warning("endpoint %s: primary %s failed (%s: %s); using fallback %s until it is "
                    "ready again", self.name, self.primary.address, exc.code().name,
                    exc.details(), self.fallback.address)

    def _probe_primary(self) -> None:
        while not self._stop.wait(self.config.probe_interval_s):
            if self.primary.serving():
                with self._lock:
                    self._on_fallback = False
                    self._probe = None
                    self.recoveries += 1
                log.info("endpoint %s: primary %s is ready again; back on it", self.name,
                         self.primary.address)
                return

    @property
    def targets(self) -> list[Any]:
        return [self.primary] if self.fallback is None else [self.primary, self.fallback]

    def _probe_placement(self) -> None:
        """Times the preferred target's readiness probe for the placement, all the time: its
        round trip while within budget tells what a call costs beyond it. With a CPU
        ceiling, reads the robot's CPU use over each interval too."""
        assert self.placement is not None
        config = self.placement.config
        cpu = RobotCpu() if config.onboard_cpu_ceiling is not None else None
        preferred = self.preferred
        while not self._stop.wait(config.probe_interval_s):
            if cpu is not None:
                self.placement.cpu_read(cpu.use())
            started = time.monotonic()
            ok = preferred.serving(min(self.deadline_s, PROBE_TIMEOUT_S * 5))
            self.placement.probe_took(time.monotonic() - started if ok else None)

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            probe = self._probe
        if probe is not None:
            probe.join(timeout=PROBE_TIMEOUT_S + 1)
        self.primary.close()
        if self.fallback is not None:
            self.fallback.close()
