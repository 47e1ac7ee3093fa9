"""Detect: an image -> detections, on ORICF's detector (oricf.v1.Detector).

The call's `labels` and `min_score` are parameters of the model's decoding (which classes
and scores survive non-maximum suppression, and so what crosses the wire). Counting,
renaming, filtering and drawing are the route's post steps (oricf.gateway.post).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from pydantic import Field

from oricf.gateway.components import CallBase, Invoke, Method
from oricf.gateway.endpoints import Endpoint, EndpointConfig
from oricf.gateway.endpoints.shared_memory import SHARED, SharedMemoryTransport
from oricf.gateway.methods.base import health_check, input_frame
from oricf.gateway.products import ProductStore
from oricf.gateway.values import Record
from oricf.imaging import Box, Detection
from oricf.models.shared_memory import SharedMemoryRef
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc


class DetectCall(CallBase):
    """oricf.v1.Detector/Detect: an image -> detections."""

    method: Literal["Detect"]
    labels: list[str] = Field(default_factory=list)
    min_score: float = Field(0.0, ge=0, le=1)


@dataclass(frozen=True)
class Detections:
    """Objects found in an image, best score first (Detect, and Infer on a detection
    model)."""

    detections: list[Detection]


def detect_request(record: Record, call: DetectCall, endpoint: EndpointConfig
                   ) -> detector_pb2.DetectRequest:
    frame = input_frame(record, "Detect")
    return detector_pb2.DetectRequest(
        image=frame.to_proto(endpoint.image.transport, endpoint.image.jpeg_quality),
        labels=call.labels, min_score=call.min_score)


def detections(response: detector_pb2.DetectResponse) -> Detections:
    return Detections([
        Detection(d.label, d.class_id, d.score,
                  Box(d.box.x_min, d.box.y_min, d.box.x_max, d.box.y_max))
        for d in response.detections])


def bind(call: DetectCall, endpoint: Endpoint, products: ProductStore) -> Invoke:
    image = endpoint.config.image
    if image.transport not in SHARED:
        return lambda record: detections(
            endpoint.call("Detect", detect_request(record, call, endpoint.config)))
    shared = SharedMemoryTransport(f"oricf-{endpoint.name}", image.transport)
    endpoint.on_close(shared.close)

    def invoke(record: Record) -> Detections:
        frame = input_frame(record, "Detect")
        pixels = frame.to_proto("raw")  # the camera's own raw encoding, or its JPEG/PNG

        def build(refs: list[SharedMemoryRef] | None) -> detector_pb2.DetectRequest:
            if refs is None:
                return detector_pb2.DetectRequest(image=pixels, labels=call.labels,
                                                  min_score=call.min_score)
            (ref,) = refs
            return detector_pb2.DetectRequest(
                image=common_pb2.Image(encoding=pixels.encoding, width=pixels.width,
                                       height=pixels.height),
                image_region=detector_pb2.SharedMemoryRef(
                    region=ref.region, offset=ref.offset, byte_size=ref.byte_size),
                labels=call.labels, min_score=call.min_score)

        return endpoint.run({"grpc": lambda target, timeout: shared.call(
            target, "Detect", timeout, [pixels.data], build,
            lambda response, _: detections(response))})

    return invoke


def result(call: Any) -> type:
    return Detections


METHOD = Method("Detect", DetectCall, "oricf.v1.Detector", detector_pb2_grpc.DetectorStub,
                health_check("oricf.v1.Detector"), result, bind, image_transport=True, rank=0)
