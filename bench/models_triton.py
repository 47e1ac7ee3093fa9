"""The ways of `oricf bench models` through NVIDIA Triton Inference Server (bench/triton.py:
the server that nvidia-pytriton bundles, YOLOX-Nano on onnxruntime in its Python back end),
side by side with the same ways through `oricf serve models`: the tensor on the wire, the
tensor in and the output back through system shared memory, and UINT8 pixels in with
decoded detections back. Asked for with `--triton`, which needs Triton's environment
(`scripts/triton-server.sh --install`)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

import grpc
import numpy as np

from oricf.bench.models_edge import Way, registered
from oricf.bench.triton import INSTALL, installed, triton_server
from oricf.gateway.endpoints import CHANNEL_OPTIONS
from oricf.gateway.methods.infer_shared import placed_outputs
from oricf.models.declaration import ModelDeclaration
from oricf.models.heads import DetectionHead
from oricf.models.shared_memory import OwnedRegion, SharedMemoryRef
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc

NETWORK, DECODED = "yolox-nano", "yolox-nano-decoded"  # scripts/triton_yolox.py
OUT_BYTES = 16 * 2**20  # room for any output of a detection network here


@contextmanager
def triton_ways(head: DetectionHead, wanted: bool) -> Iterator[dict[str, Way]]:
    """Triton's ways by name when wanted (`--triton`; main checks that it is installed)."""
    if not wanted:
        yield {}
        return
    with ExitStack() as stack:
        address = stack.enter_context(triton_server())
        channel = stack.enter_context(grpc.insecure_channel(address, options=CHANNEL_OPTIONS))
        stub = oip_grpc.GRPCInferenceServiceStub(channel)
        size = 3 * head.size[0] * head.size[1] * 4
        tensor_in = stack.enter_context(registered(stub, "bench-in", size))
        tensor_out = stack.enter_context(registered(stub, "bench-out", OUT_BYTES))
        yield _ways(head, stub, tensor_in, tensor_out)


def unusable(declaration: ModelDeclaration) -> str | None:
    """Why Triton cannot run beside ORICF's server for this model, or None."""
    if not installed():
        return f"Triton is not installed: run {INSTALL}"
    if declaration.name != NETWORK:
        return f"Triton here serves {NETWORK} only (scripts/triton_yolox.py), not " \
               f"{declaration.name}"
    return None


def _ways(head: DetectionHead, stub: oip_grpc.GRPCInferenceServiceStub,
          tensor_in: OwnedRegion, tensor_out: OwnedRegion) -> dict[str, Way]:
    score = head.task.min_score
    output = head.output or "output"
    asked = {output: SharedMemoryRef("bench-out", 0, OUT_BYTES)}

    def over_wire(frame: np.ndarray) -> object:
        prepared = head.prepare(frame)
        response = stub.ModelInfer(infer_request(NETWORK, prepared.feeds), timeout=10)
        return head.decode(response_outputs(response), prepared, score)

    def over_shm(frame: np.ndarray) -> object:
        prepared = head.prepare(frame)
        tensor = prepared.feeds[head.input_name]
        tensor_in.write(tensor.data.cast("B"))
        request = infer_request(
            NETWORK, prepared.feeds, {output: {"shared_memory_region": "bench-out",
                                               "shared_memory_byte_size": OUT_BYTES}},
            placed={head.input_name: SharedMemoryRef("bench-in", 0, tensor.nbytes)})
        outputs = placed_outputs(stub.ModelInfer(request, timeout=10), tensor_out, asked)
        return head.decode(outputs, prepared, score)

    def over_uint8(frame: np.ndarray) -> object:
        response = stub.ModelInfer(infer_request(DECODED, {head.input_name: frame}),
                                   timeout=10)
        return response_outputs(response)[output]

    return {"Triton raw tensor": over_wire, "Triton shm": over_shm,
            "Triton uint8, decoded": over_uint8}
