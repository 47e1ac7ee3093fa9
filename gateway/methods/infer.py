"""Infer: an image -> detections or classes, on any Open Inference Protocol server (KServe
v2: ORICF's `oricf serve models`, Triton, KServe, MLServer).

The model's declaration (configs/models/*.yaml) says how the gateway makes the input tensors
and reads the outputs: a detection model gives Detections (as Detect does), a
classification model gives Classes.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from functools import cached_property, partial
from typing import Any, Literal

import grpc
import numpy as np
from pydantic import Field, model_validator

from oricf.config import FilePath
from oricf.errors import ConfigError, InvalidInput
from oricf.gateway.components import CallBase, Method, MethodCall
from oricf.gateway.endpoints import Endpoint, Metadata
from oricf.gateway.endpoints.shared_memory import SHARED, SharedMemoryTransport
from oricf.gateway.methods.base import input_frame
from oricf.gateway.methods.detect import Detections
from oricf.gateway.methods.infer_shared import NotNow, output_bytes, placed_outputs
from oricf.gateway.products import ProductStore
from oricf.gateway.values import Frame, Record
from oricf.imaging import Box, Detection, encoded_size
from oricf.models.declaration import ModelDeclaration, load_declaration
from oricf.models.heads import ClassificationHead, DetectionHead, Prepared, declared_head
from oricf.models.image import geometry
from oricf.models.shared_memory import BYTE_SIZE, OFFSET, REGION, OwnedRegion, SharedMemoryRef
from oricf.models.wire import infer_request, response_outputs
from oricf.oip import open_inference_grpc_pb2 as oip
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc


class InferCall(CallBase):
    """inference.GRPCInferenceService/ModelInfer on any Open Inference Protocol server: a
    declared model's pre-processing makes its input tensors, its post-processing turns the
    outputs into fields (detection: detections; classification: classes, label, score)."""

    method: Literal["Infer"]
    model: FilePath = Field(description="the model's declaration (configs/models/*.yaml)")
    model_name: str | None = Field(
        None, description="its name on the server, if not the declaration's name")
    labels: list[str] = Field(default_factory=list, description="detection: keep only these")
    min_score: float | None = Field(None, gt=0, le=1,
                                    description="detection: default the declaration's")
    top_k: int | None = Field(None, ge=1, le=1000, description="classification")
    decoded: bool = Field(
        False, description="detection: the server pre-processes the image and returns decoded "
                           "detections, a few hundred bytes (ORICF's `oricf serve models`, or "
                           "a model on another server that takes UINT8 [H, W, 3] BGR pixels "
                           "and returns [n, 6] rows: docs/models.md)")

    @cached_property
    def declaration(self) -> ModelDeclaration:
        return load_declaration(self.model)

    @model_validator(mode="after")
    def _usable_declaration(self) -> InferCall:
        try:
            task = self.declaration.task
        except ConfigError as exc:  # named here too, so the pipeline's file and key show
            raise ValueError(f"model: {exc}") from None
        if task is None:
            raise ValueError(f"model: {self.model} declares no task; the gateway needs one "
                             f"to turn its input into tensors and its outputs into fields")
        if task.kind == "policy":
            raise ValueError(f"model: {self.model} is a policy (task.kind: policy); Infer "
                             f"calls image models: detection or classification")
        known = task.label_list()  # reads the labels file, so once
        unknown = sorted(set(self.labels) - set(known)) if known else []
        if unknown:
            raise ValueError(f"labels: the model has no label(s) {', '.join(unknown)}")
        if self.labels and task.kind != "detection":
            raise ValueError("labels: only for detection models")
        if self.top_k is not None and task.kind != "classification":
            raise ValueError("top_k: only for classification models")
        if self.decoded and task.kind != "detection":
            raise ValueError("decoded: only for detection models")
        return self

    @property
    def server_model(self) -> str:
        return self.model_name or self.declaration.name


@dataclass(frozen=True)
class Classes:
    """A classification: every class kept with its score, best first, and the best one."""

    classes: list[tuple[str, float]]
    label: str
    score: float


def server_ready(channel: grpc.Channel, timeout: float, metadata: Metadata = ()) -> bool:
    """Ready when the Open Inference Protocol's ServerReady says so: Triton, KServe and
    MLServer need not implement grpc.health.v1."""
    stub = oip_grpc.GRPCInferenceServiceStub(channel)
    return bool(stub.ServerReady(oip.ServerReadyRequest(), timeout=timeout,
                                 metadata=metadata).ready)


def _encoded_input(frame: Frame, head: DetectionHead | ClassificationHead, quality: int
                   ) -> Prepared:
    """The frame as one JPEG (or its own encoding) for the server to pre-process."""
    image = frame.to_proto("jpeg", quality)
    size = (image.width, image.height) if image.width else encoded_size(image.data)[1:]
    tensor = np.empty(1, dtype=object)
    tensor[0] = image.data
    return Prepared({head.input_name: tensor},
                    geometry(size[0], size[1], head.image, head.size), 0.0)


def _pixels_input(frame: Frame, head: DetectionHead | ClassificationHead) -> Prepared:
    """The frame as UINT8 [H, W, 3] BGR pixels for the server to pre-process."""
    pixels = frame.pixels()
    height, width = pixels.shape[:2]
    return Prepared({head.input_name: pixels},
                    geometry(width, height, head.image, head.size), 0.0)


def _decoded_detections(rows: np.ndarray, labels: list[str], min_score: float,
                        class_ids: np.ndarray | None) -> Detections:
    """The server's decoded rows (x_min, y_min, x_max, y_max, score, class id), held to the
    route's min_score and classes here too: a server other than ORICF's (Triton's Python
    back end, for one) does not see the requested output's parameters and decodes at its
    own threshold, for every class."""
    if rows.ndim != 2 or rows.shape[1] != 6:
        raise InvalidInput(f"decoded detections of shape {list(rows.shape)}; expected [n, 6]")
    wanted = None if class_ids is None else set(class_ids.tolist())
    found = []
    for x1, y1, x2, y2, score, class_id in rows.tolist():
        index = int(class_id)
        if not 0 <= index < len(labels):
            raise InvalidInput(f"decoded detection of class {index}; the model has "
                               f"{len(labels)} labels")
        if score >= min_score and (wanted is None or index in wanted):
            found.append(Detection(labels[index], index, float(score), Box(x1, y1, x2, y2)))
    return Detections(found)


class Infer(MethodCall[InferCall]):
    """A route's Infer: the declared model's head (its pre- and post-processing) resolved
    once; the input tensor on the wire, or through shared memory with room in the slot
    for the output too (image.transport: shm or auto)."""

    result = Detections  # Classes for a classification model (result_type)

    def __init__(self, call: InferCall, endpoint: Endpoint, products: ProductStore) -> None:
        super().__init__(call, endpoint, products)
        self._head = head = declared_head(call.declaration)
        self._output = output = head.output or ""
        label_ids = {label: i for i, label in enumerate(head.labels)}
        self._class_ids = (np.array(sorted(label_ids[label] for label in call.labels),
                                    np.int64) if call.labels else None)
        self._min_score = call.min_score or (  # a detection's
            head.task.min_score if isinstance(head, DetectionHead) else 0.0)
        self._transport = endpoint.config.image
        self._wanted: dict[str, dict[str, object]] = {output: {}} if output else {}
        if call.decoded and isinstance(head, DetectionHead):
            if not output:
                raise ConfigError(f"{call.model}: decoded: name the task's output (task.output)")
            self._wanted[output] = {
                "decoded": True, "min_score": self._min_score,
                **({"class_ids": ",".join(map(str, self._class_ids))}
                   if self._class_ids is not None else {})}
        self._encoding = {head.input_name: {"encoding": "bgr8"}} if call.decoded else {}
        self._shared = (SharedMemoryTransport(f"oricf-{endpoint.name}", self._transport.transport)
                        if self._transport.transport in SHARED else None)
        # Per target: the output's bytes, for its room in a slot (None: it comes on the wire).
        self._output_sizes: dict[str, int | None] = {}

    @classmethod
    def result_type(cls, call: InferCall) -> type:
        task = call.declaration.task
        return Detections if task is None or task.kind == "detection" else Classes

    def execute(self, record: Record) -> Detections | Classes:
        prepared = self._prepare(input_frame(record, "Infer"))
        if self._shared is None:
            response = self.endpoint.call("ModelInfer", self._request(prepared, {}, None))
            return self._finish(response_outputs(response), prepared)
        return self.endpoint.run({"grpc": partial(self._through_shared_memory, prepared)})

    def close(self) -> None:
        """Unregisters the shared-memory regions from the endpoint's servers."""
        if self._shared is not None:
            self._shared.close(self.endpoint.targets)

    def _prepare(self, frame: Frame) -> Prepared:
        if self._transport.transport == "jpeg":
            return _encoded_input(frame, self._head, self._transport.jpeg_quality)
        if self.call.decoded:
            return _pixels_input(frame, self._head)
        return self._head.prepare(frame.pixels())

    def _request(self, prepared: Prepared, asked: dict[str, SharedMemoryRef],
                 refs: list[SharedMemoryRef] | None) -> oip.ModelInferRequest:
        """The request, its input in the slot at refs[0] (the wire if refs is None) and its
        output at refs[1] if there is room; `asked` learns where the output was asked for
        (Triton's answer does not say)."""
        outputs = self._wanted
        asked.clear()
        if refs and len(refs) > 1:  # the output into the slot too
            asked[self._output] = refs[1]
            outputs = {self._output: {REGION: refs[1].region, OFFSET: refs[1].offset,
                                      BYTE_SIZE: refs[1].byte_size}}
        return infer_request(self.call.server_model, prepared.feeds, outputs,
                             placed={self._head.input_name: refs[0]} if refs else None,
                             input_parameters=self._encoding)

    def _through_shared_memory(self, prepared: Prepared, target: Any, timeout: float
                               ) -> Detections | Classes:
        assert self._shared is not None
        room = self._output_room(target)
        data = np.ascontiguousarray(prepared.feeds[self._head.input_name]).data.cast("B")
        asked: dict[str, SharedMemoryRef] = {}
        return self._shared.call(target, "ModelInfer", timeout,
                                 [data, *([room] if room else [])],
                                 partial(self._request, prepared, asked),
                                 partial(self._placed_answer, prepared, asked))

    def _output_room(self, target: Any) -> int | None:
        """The output's bytes on this target, asked once (None: it comes on the wire)."""
        if target.address not in self._output_sizes:
            with contextlib.suppress(NotNow):  # unknown yet: the wire this time
                self._output_sizes[target.address] = (
                    output_bytes(target, self.call.server_model, self._output)
                    if self._output and not self.call.decoded else None)
        return self._output_sizes.get(target.address)

    def _placed_answer(self, prepared: Prepared, asked: dict[str, SharedMemoryRef],
                       response: oip.ModelInferResponse, region: OwnedRegion | None
                       ) -> Detections | Classes:
        outputs = response_outputs(response, asked)
        if region is not None:
            outputs |= placed_outputs(response, region, asked)
        return self._finish(outputs, prepared)

    def _finish(self, outputs: dict[str, np.ndarray], prepared: Prepared
                ) -> Detections | Classes:
        head = self._head
        if isinstance(head, ClassificationHead):
            classes = head.decode(outputs, prepared, self.call.top_k)
            return Classes(list(zip(classes.labels, classes.scores, strict=True)),
                           classes.labels[0], classes.scores[0])
        if self.call.decoded:
            return _decoded_detections(outputs[self._output], head.labels, self._min_score,
                                       self._class_ids)
        found = head.decode(outputs, prepared, self._min_score, self._class_ids)
        return Detections([Detection(head.labels[c], int(c), float(s), Box(*map(float, b)))
                           for b, s, c in zip(found.boxes, found.scores, found.class_ids,
                                              strict=True)])


METHOD = Method("Infer", InferCall, "inference.GRPCInferenceService",
                oip_grpc.GRPCInferenceServiceStub, server_ready, Infer,
                image_transport=True, takes_tensors=True, rank=3)
