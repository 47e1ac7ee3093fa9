"""inference.GRPCInferenceService (the Open Inference Protocol) over declared models.

ModelInfer runs a model on its own tensors. For a model with an image task, its image
input may instead come as an encoded image or raw UINT8 pixels (services/models/images.py):
the service decodes it, refusing oversized or lying images, and applies the declared
pre-processing; a detection model then also returns decoded detections when asked
(services/models/decoded.py). That is how a remote gateway sends camera frames as JPEG and
gets a few hundred bytes back. Inputs and outputs may name regions of system shared memory
(SharedMemoryServicer) instead of carrying their bytes, as with Triton. A declared control
policy is refused NaN or infinity in its inputs and never answers them, as in the Policy
service.
"""

from __future__ import annotations

import logging
from contextlib import ExitStack

import grpc
import numpy as np

from oricf import __version__
from oricf.errors import InvalidInput, NotFound
from oricf.models.declared import DeclaredModel
from oricf.models.policy import require_finite_answer, require_finite_inputs
from oricf.models.policy_task import PolicyTask
from oricf.models.shared_memory import SharedMemoryRef, tensor_ref
from oricf.models.tensors import clip
from oricf.models.wire import (
    infer_response,
    parameter_value,
    request_bytes,
    request_inputs,
    to_raw,
)
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.services.models.batching import Feeds, rows_of
from oricf.services.models.config import ModelsConfig
from oricf.services.models.decoded import decode_ask, decoded
from oricf.services.models.images import image_feeds
from oricf.services.models.repository import ModelRepository
from oricf.services.runtime import ModelSlot
from oricf.services.runtime.batch_calls import run_batched
from oricf.services.runtime.batching import Batcher
from oricf.services.runtime.errors import check_deadline
from oricf.services.runtime.limits import MemoryBudget
from oricf.services.runtime.shared_memory import SharedMemoryRegistry
from oricf.services.runtime.shared_memory_rpcs import SharedMemoryServicer

log = logging.getLogger(__name__)

VERSION = "1"  # every declared model is served as its one version
PLATFORMS = {"onnxruntime": "onnxruntime_onnx", "openvino": "openvino"}
# A network's intermediate tensors grow with its input's shape, to several times its bytes:
# an input tensor counts this many times its own size against the memory budget.
TENSOR_WORK_FACTOR = 8


class InferenceServicer(SharedMemoryServicer):
    def __init__(self, slot: ModelSlot[ModelRepository], config: ModelsConfig,
                 batchers: dict[str, Batcher[Feeds, Feeds]] | None = None,
                 shared_memory: SharedMemoryRegistry | None = None) -> None:
        super().__init__(shared_memory)
        self.slot = slot
        self.config = config
        self.batchers = batchers or {}
        self.budget = MemoryBudget(config.server.max_inflight_bytes,
                                   config.server.retry_after_ms)

    def ServerLive(self, request: oip.ServerLiveRequest, context: grpc.ServicerContext
                   ) -> oip.ServerLiveResponse:
        return oip.ServerLiveResponse(live=True)

    def ServerReady(self, request: oip.ServerReadyRequest, context: grpc.ServicerContext
                    ) -> oip.ServerReadyResponse:
        return oip.ServerReadyResponse(ready=self.slot.ready)

    def ServerMetadata(self, request: oip.ServerMetadataRequest,
                       context: grpc.ServicerContext) -> oip.ServerMetadataResponse:
        return oip.ServerMetadataResponse(name="oricf", version=__version__)

    def ModelReady(self, request: oip.ModelReadyRequest, context: grpc.ServicerContext
                   ) -> oip.ModelReadyResponse:
        self._model(request.name, request.version, loaded=False)
        return oip.ModelReadyResponse(ready=self.slot.ready)

    def ModelMetadata(self, request: oip.ModelMetadataRequest,
                      context: grpc.ServicerContext) -> oip.ModelMetadataResponse:
        model = self._model(request.name, request.version)
        declaration = model.declaration
        response = oip.ModelMetadataResponse(
            name=model.name, versions=[VERSION],
            platform=PLATFORMS[declaration.backend.engine])
        for spec in model.inputs:
            response.inputs.add(name=spec.name, datatype=spec.datatype, shape=spec.shape)
        for spec in model.outputs:
            response.outputs.add(name=spec.name, datatype=spec.datatype, shape=spec.shape)
        info = model.info()
        response.properties.update({"runtime": info.runtime, "license": info.license,
                                    "sha256": info.sha256})
        if declaration.task is not None:
            response.properties["task"] = declaration.task.kind
        return response

    def ModelInfer(self, request: oip.ModelInferRequest, context: grpc.ServicerContext
                   ) -> oip.ModelInferResponse:
        model = self._model(request.model_name, request.model_version)
        wanted = self._wanted_outputs(model, request)
        ask = decode_ask(model, list(request.outputs))
        placed = self._placed_outputs(request)
        with ExitStack() as held:  # what the call holds of the budget, until it ends
            held.enter_context(self.budget.hold(request_bytes(request) * TENSOR_WORK_FACTOR,
                                                "the request's tensors"))
            read = self.shared_memory.read if self.shared_memory is not None else None
            feeds, prepared = image_feeds(model, request_inputs(request, read),
                                          _image_encoding(model, request),
                                          self.config.images.max_pixels, self.budget.hold)
            unknown = sorted(set(feeds) - {spec.name for spec in model.inputs})
            if unknown:
                raise InvalidInput(f"model {model.name} has no input '{clip(unknown[0])}' "
                                   f"(inputs: {', '.join(s.name for s in model.inputs)})")
            policy = isinstance(model.declaration.task, PolicyTask)
            if policy:  # as the Policy service: never an action from NaN or infinity
                require_finite_inputs(feeds)
            # Decoding may have taken the caller's whole deadline: no one waits for the rest.
            check_deadline(context, "before inference could start")
            batcher = self.batchers.get(model.name)
            outputs = model.infer(feeds) if batcher is None else \
                self._batched(batcher, model, feeds, context)
            if policy:
                require_finite_answer(model.name, outputs)
            if ask is not None:
                outputs = {**outputs, ask.output: decoded(model, ask, outputs, prepared)}
            if wanted:
                outputs = {name: outputs[name] for name in wanted}
            response = infer_response(model.name, outputs, request.id, placed)
            self._write_placed(outputs, placed)
        response.model_version = VERSION
        return response

    @staticmethod
    def _wanted_outputs(model: DeclaredModel, request: oip.ModelInferRequest) -> list[str]:
        wanted = [o.name for o in request.outputs]
        known = {spec.name for spec in model.outputs}
        for name in wanted:
            if name not in known:
                raise InvalidInput(f"model {model.name} has no output '{clip(name)}' "
                                   f"(outputs: {', '.join(sorted(known))})")
        return wanted

    def _placed_outputs(self, request: oip.ModelInferRequest) -> dict[str, SharedMemoryRef]:
        """The requested outputs that go to shared memory, by name."""
        placed = {}
        for output in request.outputs:
            ref = tensor_ref(output.parameters, f"output '{clip(output.name)}'")
            if ref is not None:
                if self.shared_memory is None:
                    raise InvalidInput(f"output '{clip(output.name)}': shared memory is off "
                                       f"on this server")
                placed[output.name] = ref
        return placed

    def _write_placed(self, outputs: dict[str, np.ndarray],
                      placed: dict[str, SharedMemoryRef]) -> None:
        for name, ref in placed.items():
            assert self.shared_memory is not None
            self.shared_memory.write(ref, to_raw(outputs[name])[1])

    @staticmethod
    def _batched(batcher: Batcher[Feeds, Feeds], model: DeclaredModel, feeds: Feeds,
                 context: grpc.ServicerContext) -> Feeds:
        rows_of(model, feeds, batcher.settings.max_batch_size)
        return run_batched(batcher, feeds, context)

    def _model(self, name: str, version: str, loaded: bool = True) -> DeclaredModel:
        """The named model (NOT_FOUND for an unknown name or version); UNAVAILABLE while
        loading unless loaded=False."""
        model = (self.slot.get() if loaded else self.slot.peek()).get(name)
        if version not in ("", VERSION):
            raise NotFound(f"model {model.name} has no version '{clip(version)}' "
                           f"(served: {VERSION})")
        return model


def _image_encoding(model: DeclaredModel, request: oip.ModelInferRequest) -> str:
    """The `encoding` parameter of the image input, "" if none."""
    head = model.head
    for tensor in request.inputs:
        if head is not None and tensor.name == head.input_name and "encoding" in tensor.parameters:
            value = parameter_value(tensor.parameters["encoding"])
            if not isinstance(value, str):
                raise InvalidInput(f"input '{clip(tensor.name)}': encoding must be a string")
            return value
    return ""
