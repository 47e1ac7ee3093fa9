"""Detect: an image -> detections, on ORICF's detector (oricf.v1.Detector).

The call's `labels` and `min_score` are parameters of the model's decoding (which classes
and scores survive non-maximum suppression, and so what crosses the wire). Counting,
renaming, filtering and drawing are the route's post steps (oricf.gateway.post).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Literal

from pydantic import Field

from oricf.gateway.components import CallBase, Method, MethodCall
from oricf.gateway.endpoints import Endpoint, EndpointConfig, GrpcTarget
from oricf.gateway.endpoints.shared_memory import SHARED, SharedMemoryTransport
from oricf.gateway.methods.base import ServingHealth, input_frame
from oricf.gateway.products import ProductStore
from oricf.gateway.values import Record
from oricf.imaging import Box, Detection
from oricf.models.shared_memory import OwnedRegion, SharedMemoryRef
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


class Detect(MethodCall[DetectCall]):
    """A route's Detect: the frame on the wire as the endpoint's image settings say, or
    its pixels through shared memory (image.transport: shm or auto)."""

    result = Detections

    def __init__(self, call: DetectCall, endpoint: Endpoint, products: ProductStore) -> None:
        super().__init__(call, endpoint, products)
        image = endpoint.config.image
        self._shared = (SharedMemoryTransport(f"oricf-{endpoint.name}", image.transport)
                        if image.transport in SHARED else None)

    def execute(self, record: Record) -> Detections:
        if self._shared is None:
            return detections(self.endpoint.call(
                "Detect", detect_request(record, self.call, self.endpoint.config)))
        # the camera's own raw encoding, or its JPEG/PNG
        pixels = input_frame(record, "Detect").to_proto("raw")
        return self.endpoint.run({"grpc": partial(self._through_shared_memory, pixels)})

    def _through_shared_memory(self, pixels: common_pb2.Image, target: GrpcTarget,
                               timeout: float) -> Detections:
        assert self._shared is not None
        return self._shared.call(target, "Detect", timeout, [pixels.data],
                                 partial(self._placed_request, pixels), self._answer)

    def _placed_request(self, pixels: common_pb2.Image, refs: list[SharedMemoryRef] | None
                        ) -> detector_pb2.DetectRequest:
        """The request naming where the pixels are; on the wire (refs None) carrying them."""
        if refs is None:
            return detector_pb2.DetectRequest(image=pixels, labels=self.call.labels,
                                              min_score=self.call.min_score)
        (ref,) = refs
        return detector_pb2.DetectRequest(
            image=common_pb2.Image(encoding=pixels.encoding, width=pixels.width,
                                   height=pixels.height),
            image_region=detector_pb2.SharedMemoryRef(
                region=ref.region, offset=ref.offset, byte_size=ref.byte_size),
            labels=self.call.labels, min_score=self.call.min_score)

    @staticmethod
    def _answer(response: detector_pb2.DetectResponse, region: OwnedRegion | None
                ) -> Detections:
        return detections(response)

    def close(self) -> None:
        """Unregisters the shared-memory regions from the endpoint's servers."""
        if self._shared is not None:
            self._shared.close(self.endpoint.targets)


METHOD = Method("Detect", DetectCall, "oricf.v1.Detector", detector_pb2_grpc.DetectorStub,
                ServingHealth("oricf.v1.Detector"), Detect, image_transport=True, rank=0)
