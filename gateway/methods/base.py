"""What the method modules share: the health probe of ORICF's own services, and the camera
frame of a record. What a method is (Method, MethodCall, CallBase, Partial, Skip) is the
core's (oricf.gateway.components)."""

from __future__ import annotations

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.errors import InvalidInput
from oricf.gateway.endpoints import Metadata
from oricf.gateway.values import Frame, Record


class ServingHealth:
    """Ready when grpc.health.v1 says the service is SERVING (ORICF's own services): a
    method's readiness probe (endpoints.Ready)."""

    def __init__(self, service: str) -> None:
        self.service = service

    def __call__(self, channel: grpc.Channel, timeout: float, metadata: Metadata = ()
                 ) -> bool:
        reply = health_pb2_grpc.HealthStub(channel).Check(
            health_pb2.HealthCheckRequest(service=self.service), timeout=timeout,
            metadata=metadata)
        return bool(reply.status == health_pb2.HealthCheckResponse.SERVING)


def input_frame(record: Record, method: str) -> Frame:
    frame = record.get("image")
    if not isinstance(frame, Frame):
        raise InvalidInput(f"{method} needs an image input")
    return frame
