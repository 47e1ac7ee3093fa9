"""What the method modules share: the health probe of ORICF's own services, and the camera
frame of a record. What a method is (Method, CallBase, Partial, Skip) is the core's
(oricf.gateway.components)."""

from __future__ import annotations

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.errors import InvalidInput
from oricf.gateway.endpoints import Metadata, Ready
from oricf.gateway.values import Frame, Record


def health_check(service: str) -> Ready:
    """Ready when grpc.health.v1 says the service is SERVING (ORICF's own services)."""
    def ready(channel: grpc.Channel, timeout: float, metadata: Metadata = ()) -> bool:
        reply = health_pb2_grpc.HealthStub(channel).Check(
            health_pb2.HealthCheckRequest(service=service), timeout=timeout,
            metadata=metadata)
        return bool(reply.status == health_pb2.HealthCheckResponse.SERVING)

    return ready


def input_frame(record: Record, method: str) -> Frame:
    frame = record.get("image")
    if not isinstance(frame, Frame):
        raise InvalidInput(f"{method} needs an image input")
    return frame
