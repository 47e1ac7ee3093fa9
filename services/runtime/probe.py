"""A plaintext listener that answers grpc.health.v1 Check and nothing else.

Kubernetes' gRPC probes (and other orchestrators' plaintext checks) cannot present a client
certificate, so they cannot reach a service that requires mTLS. `server.health_listen` gives
them a second port that answers only Check, from the same HealthServicer as the service's
own port: it says SERVING or not and carries nothing else. Watch is not served there (a
probe never watches), so a caller on that port cannot hold streams open either; clients
that watch (the gateway's round robin) do so over the service's own, authenticated port.
"""

from __future__ import annotations

from concurrent import futures

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc

from oricf.errors import ConfigError

# Check answers from memory at once: two threads serve any number of probes in turn.
PROBE_WORKERS = 2


class CheckOnly(health_pb2_grpc.HealthServicer):
    """Check from the service's HealthServicer; Watch answered UNIMPLEMENTED (the base)."""

    def __init__(self, servicer: health.HealthServicer) -> None:
        self._servicer = servicer

    def Check(self, request: health_pb2.HealthCheckRequest,
              context: grpc.ServicerContext) -> health_pb2.HealthCheckResponse:
        return self._servicer.Check(request, context)


def probe_server(servicer: health.HealthServicer, address: str) -> tuple[grpc.Server, int]:
    """The health-only server bound to address (not started) and its port."""
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=PROBE_WORKERS,
                                                    thread_name_prefix="health-probe"),
                         options=[("grpc.so_reuseport", 0)])
    health_pb2_grpc.add_HealthServicer_to_server(CheckOnly(servicer), server)
    try:
        port = server.add_insecure_port(address)
    except RuntimeError as exc:
        raise ConfigError(f"server.health_listen: cannot listen on {address}: {exc}") from None
    if port == 0:
        raise ConfigError(f"server.health_listen: cannot listen on {address} (port in use?)")
    return server, port
