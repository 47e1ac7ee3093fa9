"""A gRPC server as an endpoint's target: a channel (TLS if configured, replicas balanced
by gRPC itself), the service's stub, the call metadata and the readiness probe."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

import grpc

from oricf.gateway.endpoints.config import TargetConfig
from oricf.gateway.endpoints.replicas import channel_options
from oricf.tls import open_channel
from oricf.tracing import inject

# Short reconnect backoff: a restarted service is found within about a second, not the
# default of up to two minutes. gRPC uses the minimum as the time a connection attempt has
# to complete (the default is 20 s): 3 s, because Linux resends a lost SYN after 1 s, and
# with 1 s one lost packet of the handshake on a lossy link failed the attempt, and the
# endpoint failed over. A host that never completes the handshake is bounded by each call's
# deadline (the endpoint fails over on DEADLINE_EXCEEDED).
#
# No BDP probing: gRPC pings the server after every response it reads to size its receive
# window, which woke about two of grpcio's threads per call. Replies are small (detections,
# text), so a fixed 8 MB window serves as well. Requests are governed by the server's
# window, which is unaffected.
CHANNEL_OPTIONS = [
    ("grpc.max_send_message_length", 64 * 1024 * 1024),
    ("grpc.max_receive_message_length", 64 * 1024 * 1024),
    ("grpc.initial_reconnect_backoff_ms", 250),
    ("grpc.min_reconnect_backoff_ms", 3000),
    ("grpc.max_reconnect_backoff_ms", 1000),
    ("grpc.http2.bdp_probe", 0),
    ("grpc.http2.lookahead_bytes", 8 * 1024 * 1024),
]

RECEIVE_LIMIT = "grpc.max_receive_message_length"

Metadata = tuple[tuple[str, str], ...]
Stub = Callable[[grpc.Channel], Any]
# Whether the server behind a channel is ready for calls (timeout, call metadata).
Ready = Callable[[grpc.Channel, float, Metadata], bool]


def receiving(options: Sequence[tuple[str, object]], reply_bytes: int | None
              ) -> list[tuple[str, object]]:
    """options, with answers larger than reply_bytes refused: gRPC reads a message's length
    first and ends the call with RESOURCE_EXHAUSTED before it holds the message."""
    if reply_bytes is None:
        return list(options)
    limit = dict(options).get(RECEIVE_LIMIT)
    if isinstance(limit, int):
        reply_bytes = min(limit, reply_bytes)
    return [*(option for option in options if option[0] != RECEIVE_LIMIT),
            (RECEIVE_LIMIT, reply_bytes)]


def refused_as_too_large(exc: grpc.RpcError) -> bool:
    """Whether gRPC itself ended a call for an answer over the channel's limit: told as
    RESOURCE_EXHAUSTED, as a busy server is, but no retry would be answered otherwise."""
    return (exc.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
            and "larger than max" in (exc.details() or ""))


class Service(Protocol):
    """What a gRPC target needs of the service it calls (a method's entry has both)."""

    @property
    def stub(self) -> Stub: ...

    @property
    def ready(self) -> Ready: ...


class GrpcTarget:
    protocol = "grpc"

    def __init__(self, config: TargetConfig, service: Service,
                 reply_bytes: int | None = None) -> None:
        """`reply_bytes`: the largest answer taken (within the channel's own limit)."""
        self.address = config.address
        self.channel = open_channel(config.address, config.tls,
                                    channel_options(config.address,
                                                    receiving(CHANNEL_OPTIONS, reply_bytes)))
        self.stub = service.stub(self.channel)
        token = config.token.tokens()[0] if config.token else None
        self.metadata: Metadata = (
            () if token is None else ((config.token_header, token),) if config.token_header
            else (("authorization", f"Bearer {token}"),))
        self._ready = service.ready

    def invoke(self, rpc: str, request: Any, timeout: float) -> Any:
        # With the caller's trace context (`traceparent`) while tracing is on: the service's
        # span of this call joins the route's trace.
        return getattr(self.stub, rpc)(request, metadata=inject(self.metadata), timeout=timeout)

    def serving(self, timeout: float = 1.0) -> bool:
        try:
            return self._ready(self.channel, timeout, self.metadata)
        except grpc.RpcError:
            return False

    def close(self) -> None:
        self.channel.close()
