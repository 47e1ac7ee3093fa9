"""The detector as a runtime service: `oricf serve detector`, for any declared detection model."""

from __future__ import annotations

import grpc

from oricf.errors import ConfigError
from oricf.models.declaration import DetectionTask, load_declaration
from oricf.models.declared import DeclaredModel, FixedBatch
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.services import SERVICES
from oricf.services.detector.config import DetectorConfig
from oricf.services.detector.labels import LabelSpace
from oricf.services.detector.servicer import DetectorServicer
from oricf.services.runtime import ModelSlot, ServiceParts
from oricf.services.runtime.batching import Batcher
from oricf.services.runtime.shared_memory import SharedMemoryRegistry
from oricf.services.runtime.shared_memory_rpcs import SharedMemoryServicer
from oricf.store import ModelStore
from oricf.v1 import detector_pb2_grpc


def create_model(config: DetectorConfig, store: ModelStore) -> DeclaredModel:
    declaration = load_declaration(config.model)
    if not isinstance(declaration.task, DetectionTask):
        raise ConfigError(f"{config.model}: task.kind: the detector serves detection models")
    batching = config.batching
    fixed = (None if batching is None
             else FixedBatch(batching.max_batch_size, batching.fixed_size))
    return DeclaredModel(declaration, store, batched=batching is not None, fixed_batch=fixed)


def add_servicer(server: grpc.Server, slot: ModelSlot[DeclaredModel],
                 config: DetectorConfig) -> None:
    task = slot.peek().declaration.task  # create_model checked it is a detection task
    assert isinstance(task, DetectionTask)
    detection = config.detection
    labels = LabelSpace(task.label_list(), detection.labels)
    min_score = detection.min_score or task.min_score
    batcher = None
    if config.batching is not None:
        # The model object itself, loaded or not: the batcher drains before it closes.
        batcher = Batcher(PARTS.name, config.batching, slot.peek().detect_batch,
                          config.server.retry_after_ms)
        slot.attach(batcher)
    registry = (SharedMemoryRegistry(config.shared_memory) if config.shared_memory.enabled
                else None)
    detector_pb2_grpc.add_DetectorServicer_to_server(
        DetectorServicer(slot, config, labels, min_score, batcher, registry), server)
    if registry is not None:  # clients register the regions that requests name
        oip_grpc.add_GRPCInferenceServiceServicer_to_server(SharedMemoryServicer(registry),
                                                            server)


PARTS = ServiceParts(
    SERVICES["detector"],
    config_schema=DetectorConfig,
    create_model=create_model,
    add_servicer=add_servicer,
)
