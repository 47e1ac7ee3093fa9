"""The ways of `oricf bench models` that move fewer bytes: shared memory onboard (the tensor
in and the output back through registered regions; the typed Detect with its frame in a
region), and to the edge (raw UINT8 pixels, or the frame as JPEG, with decoded detections
back instead of the output tensor)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from oricf.bench.common import JPEG_QUALITY
from oricf.gateway.methods.infer_shared import placed_outputs
from oricf.imaging import encode_image
from oricf.models.declaration import ModelDeclaration
from oricf.models.heads import DetectionHead
from oricf.models.shared_memory import OwnedRegion, SharedMemoryRef
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.v1 import common_pb2, detector_pb2, detector_pb2_grpc

Way = Callable[[np.ndarray], object]
FRAME_BYTES = 640 * 480 * 3


@contextmanager
def registered(stub: oip_grpc.GRPCInferenceServiceStub, name: str, byte_size: int
               ) -> Iterator[OwnedRegion]:
    region = OwnedRegion(byte_size)
    try:
        stub.SystemSharedMemoryRegister(oip.SystemSharedMemoryRegisterRequest(
            name=name, key=region.key, byte_size=byte_size), timeout=10)
        region.release_name()
        yield region
    finally:
        stub.SystemSharedMemoryUnregister(oip.SystemSharedMemoryUnregisterRequest(name=name),
                                          timeout=10)
        region.close()


@contextmanager
def edge_ways(declaration: ModelDeclaration, head: DetectionHead,
              models: oip_grpc.GRPCInferenceServiceStub,
              detector: oip_grpc.GRPCInferenceServiceStub,
              typed: detector_pb2_grpc.DetectorStub) -> Iterator[dict[str, Way]]:
    score = head.task.min_score
    output = head.output or "output"
    size = 3 * head.size[0] * head.size[1] * 4
    out_size = 16 * 2**20  # room for any output of a detection network here
    decoded = {output: {"decoded": True, "min_score": score}}

    with registered(models, "bench-in", size) as tensor_in, \
            registered(models, "bench-out", out_size) as tensor_out, \
            registered(detector, "bench-frame", FRAME_BYTES) as frame_region:

        def over_shm(frame: np.ndarray) -> object:
            prepared = head.prepare(frame)
            tensor = prepared.feeds[head.input_name]
            tensor_in.write(tensor.data.cast("B"))
            request = infer_request(
                declaration.name, prepared.feeds,
                {output: {"shared_memory_region": "bench-out",
                          "shared_memory_byte_size": out_size}},
                placed={head.input_name: SharedMemoryRef("bench-in", 0, tensor.nbytes)})
            outputs = placed_outputs(models.ModelInfer(request, timeout=10), tensor_out)
            return head.decode(outputs, prepared, score)

        def over_uint8(frame: np.ndarray) -> object:
            response = models.ModelInfer(infer_request(
                declaration.name, {head.input_name: frame}, decoded,
                input_parameters={head.input_name: {"encoding": "bgr8"}}), timeout=10)
            return response_outputs(response)[output]

        def over_jpeg(frame: np.ndarray) -> object:
            tensor = np.empty(1, dtype=object)
            tensor[0] = encode_image(frame, "jpeg", JPEG_QUALITY)
            response = models.ModelInfer(infer_request(
                declaration.name, {head.input_name: tensor}, decoded), timeout=10)
            return response_outputs(response)[output]

        def over_detect_shm(frame: np.ndarray) -> object:
            frame_region.write(np.ascontiguousarray(frame).data.cast("B"))
            return typed.Detect(detector_pb2.DetectRequest(
                image=common_pb2.Image(encoding="bgr8", width=frame.shape[1],
                                       height=frame.shape[0]),
                image_region=detector_pb2.SharedMemoryRef(region="bench-frame",
                                                          byte_size=frame.nbytes)),
                timeout=10)

        yield {"ModelInfer shm": over_shm, "ModelInfer uint8, decoded": over_uint8,
               "ModelInfer jpeg, decoded": over_jpeg, "Detect bgr8 shm": over_detect_shm}
