"""A model service endpoint with a deadline on every call and failover to a fallback.

State machine (per endpoint):

    PRIMARY --call fails UNAVAILABLE / DEADLINE_EXCEEDED--> FALLBACK (the call is retried there)
    FALLBACK --health probe of the primary says SERVING--> PRIMARY

A call a service refuses as busy (RESOURCE_EXHAUSTED) is retried on the same target after
the wait the service asked for (grpc-retry-pushback-ms) or an exponential backoff with
jitter, whichever is longer, while its deadline allows (`retry:` in the endpoint's YAML).

While on the fallback a background thread asks the primary's grpc.health.v1 service every
probe_interval_s. Without a fallback, errors go back to the caller (the route logs them).

An address or fallback may name several replicas (dns:///NAME:PORT, ipv4:A:P,B:P): gRPC
then balances calls over the healthy ones and retries a call on another replica when one
dies under it (gateway/replicas.py); the endpoint fails over only once none is left.
"""

from __future__ import annotations

import itertools
import logging
import random
import threading
import time
from collections.abc import Callable
from typing import Any, Literal, Protocol

import grpc
from pydantic import Field, field_validator, model_validator

from oricf.config import Schema
from oricf.gateway.replicas import channel_options, check_target, several_addresses
from oricf.tls import ClientTls, TokenSource, open_channel

log = logging.getLogger(__name__)

FAILOVER_CODES = frozenset({grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED})
# Short reconnect backoff: a restarted service is found within about a second, not the
# default of up to two minutes. gRPC also uses the minimum as the connect timeout, so a host
# that accepts connections but never completes the handshake fails within a second too.
#
# No BDP probing: gRPC pings the server after every response it reads to size its receive
# window, which woke about two of grpcio's threads per call. Replies are small (detections,
# text) or at most an annotated frame, so a fixed 8 MB window serves as well: an annotated
# 640x480 frame (0.9 MB) arrives without waiting for window updates. Requests are governed
# by the server's window, which is unaffected.
CHANNEL_OPTIONS = [
    ("grpc.max_send_message_length", 64 * 1024 * 1024),
    ("grpc.max_receive_message_length", 64 * 1024 * 1024),
    ("grpc.initial_reconnect_backoff_ms", 250),
    ("grpc.min_reconnect_backoff_ms", 1000),
    ("grpc.max_reconnect_backoff_ms", 1000),
    ("grpc.http2.bdp_probe", 0),
    ("grpc.http2.lookahead_bytes", 8 * 1024 * 1024),
]
PROBE_TIMEOUT_S = 1.0

Metadata = tuple[tuple[str, str], ...]
Stub = Callable[[grpc.Channel], Any]
# Whether the server behind a channel is ready for calls (timeout, call metadata).
Ready = Callable[[grpc.Channel, float, Metadata], bool]


class Service(Protocol):
    """What an endpoint needs of the service it calls (a method's entry has both)."""

    @property
    def stub(self) -> Stub: ...

    @property
    def ready(self) -> Ready: ...


class ImageTransport(Schema):
    transport: Literal["raw", "jpeg"] = Field(
        "raw", description="raw pixels (onboard: no encode cost) or jpeg (remote: less bandwidth)")
    jpeg_quality: int = Field(80, ge=1, le=100)


class RetryConfig(Schema):
    """Retries of a call the service refused as busy (RESOURCE_EXHAUSTED), within its
    deadline: wait the service's pushback, or exponential backoff with jitter if longer."""

    attempts: int = Field(2, ge=0, le=10, description="retries after the first refusal")
    initial_backoff_ms: int = Field(50, ge=1, le=60_000)
    max_backoff_ms: int = Field(1000, ge=1, le=600_000)


class EndpointConfig(Schema):
    address: str = Field(description="host:port, or replicas to balance over: "
                                     "dns:///NAME:PORT, ipv4:IP:PORT,IP:PORT,... "
                                     "(gateway/replicas.py)")
    fallback: str | None = Field(None, description="used while the primary is unavailable")
    deadline_ms: int = Field(1000, gt=0, le=600_000, description="per call")
    probe_interval_s: float = Field(
        1.0, gt=0, le=60, description="health probe of the primary while on the fallback")
    image: ImageTransport = ImageTransport()
    retry: RetryConfig = RetryConfig()
    tls: ClientTls | None = Field(None, description="TLS to the service (mTLS with cert/key)")
    token: TokenSource | None = Field(None, description="bearer token sent with every call")

    @field_validator("address", "fallback")
    @classmethod
    def _target(cls, value: str | None) -> str | None:
        return None if value is None else check_target(value)

    @model_validator(mode="after")
    def _tls_name(self) -> EndpointConfig:
        listed = [t for t in (self.address, self.fallback) if t and several_addresses(t)]
        if self.tls is not None and self.tls.server_name is None and listed:
            raise ValueError(f"tls.server_name is needed with several addresses in one "
                             f"target ({listed[0]}): the name the replicas' certificate has")
        return self


def _pushback_ms(exc: grpc.RpcError) -> float:
    """The wait the service asked for (gRPC's grpc-retry-pushback-ms), 0 if none."""
    metadata = dict(exc.trailing_metadata() or ())  # type: ignore[attr-defined]
    try:
        return max(0.0, float(metadata.get("grpc-retry-pushback-ms", 0)))
    except (TypeError, ValueError):
        return 0.0


class Target:
    """One address: a channel (TLS if configured), the service's stub, the call metadata (a
    bearer token if configured) and the readiness probe."""

    def __init__(self, address: str, service: Service, tls: ClientTls | None = None,
                 token: str | None = None) -> None:
        self.address = address
        self.channel = open_channel(address, tls, channel_options(address, CHANNEL_OPTIONS))
        self.stub = service.stub(self.channel)
        self.metadata: Metadata = (("authorization", f"Bearer {token}"),) if token else ()
        self._ready = service.ready

    def serving(self) -> bool:
        try:
            return self._ready(self.channel, PROBE_TIMEOUT_S, self.metadata)
        except grpc.RpcError:
            return False

    def close(self) -> None:
        self.channel.close()


class Endpoint:
    """A service the routes call: `service.stub` makes its client on a channel,
    `service.ready` asks whether a server is ready (the probe that ends a failover)."""

    def __init__(self, name: str, config: EndpointConfig, service: Service) -> None:
        self.name = name
        self.config = config
        token = config.token.tokens()[0] if config.token else None
        self.primary = Target(config.address, service, config.tls, token)
        self.fallback = (Target(config.fallback, service, config.tls, token)
                         if config.fallback else None)
        self.failovers = 0
        self.recoveries = 0
        self.retries = 0
        self._on_fallback = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._probe: threading.Thread | None = None

    @property
    def deadline_s(self) -> float:
        return self.config.deadline_ms / 1000.0

    @property
    def active(self) -> Target:
        with self._lock:
            return self.fallback if self._on_fallback and self.fallback else self.primary

    def call(self, rpc: str, request: Any) -> Any:
        """Calls rpc on the active target; fails over once on UNAVAILABLE/DEADLINE_EXCEEDED."""
        target = self.active
        try:
            return self._call(target, rpc, request)
        except grpc.RpcError as exc:
            if self.fallback is None or target is self.fallback or exc.code() not in FAILOVER_CODES:
                raise
            self._fail_over(exc)
            return self._call(self.fallback, rpc, request)

    def _call(self, target: Target, rpc: str, request: Any) -> Any:
        """One target, its deadline, and retries while it refuses the call as busy."""
        deadline = time.monotonic() + self.deadline_s
        for attempt in itertools.count(1):
            try:
                return getattr(target.stub, rpc)(request, metadata=target.metadata,
                                                 timeout=max(deadline - time.monotonic(), 0.001))
            except grpc.RpcError as exc:
                wait = self._retry_wait(exc, attempt, deadline - time.monotonic())
                if wait is None:
                    raise
                self.retries += 1
                log.debug("endpoint %s: %s busy, retry %d in %.0f ms", self.name,
                          target.address, attempt, wait * 1000)
                time.sleep(wait)
        raise AssertionError("unreachable")

    def _retry_wait(self, exc: grpc.RpcError, attempt: int, remaining: float) -> float | None:
        """Seconds to wait before retrying a refused call, or None to give up."""
        retry = self.config.retry
        if exc.code() != grpc.StatusCode.RESOURCE_EXHAUSTED or attempt > retry.attempts:
            return None
        backoff = min(retry.max_backoff_ms, retry.initial_backoff_ms * 2 ** (attempt - 1))
        wait_ms = max(backoff * random.uniform(0.5, 1.5), _pushback_ms(exc))
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
        log.warning("endpoint %s: primary %s failed (%s); using fallback %s until it is "
                    "SERVING again", self.name, self.primary.address, exc.code().name,
                    self.fallback.address)

    def _probe_primary(self) -> None:
        while not self._stop.wait(self.config.probe_interval_s):
            if self.primary.serving():
                with self._lock:
                    self._on_fallback = False
                    self._probe = None
                    self.recoveries += 1
                log.info("endpoint %s: primary %s is SERVING again; back on it", self.name,
                         self.primary.address)
                return

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            probe = self._probe
        if probe is not None:
            probe.join(timeout=PROBE_TIMEOUT_S + 1)
        self.primary.close()
        if self.fallback is not None:
            self.fallback.close()
