"""Declared models over the Open Inference Protocol: `oricf serve models`."""

from __future__ import annotations

import grpc

from oricf.models.declaration import load_declaration
from oricf.models.declared import FixedBatch
from oricf.oip import open_inference_grpc_pb2_grpc as oip_grpc
from oricf.services import SERVICES
from oricf.services.models.batching import batch_runner
from oricf.services.models.config import ModelsConfig
from oricf.services.models.repository import ModelRepository
from oricf.services.models.servicer import InferenceServicer
from oricf.services.runtime import ModelSlot, ServiceParts
from oricf.services.runtime.batching import Batcher
from oricf.services.runtime.shared_memory import SharedMemoryRegistry
from oricf.store import ModelStore


def create_model(config: ModelsConfig, store: ModelStore) -> ModelRepository:
    batched = {name: FixedBatch(settings.max_batch_size, settings.fixed_size)
               for name, settings in config.batching.items()}
    return ModelRepository((load_declaration(path) for path in config.models), store,
                           batched=batched)


def add_servicer(server: grpc.Server, slot: ModelSlot[ModelRepository],
                 config: ModelsConfig) -> None:
    batchers = {}
    for name, settings in config.batching.items():
        model = slot.peek().get(name)
        batchers[name] = Batcher(f"{PARTS.name}/{name}", settings,
                                 batch_runner(model, settings.max_batch_size),
                                 config.server.retry_after_ms)
        slot.attach(batchers[name])
    shared = config.shared_memory
    registry = SharedMemoryRegistry(shared) if shared.enabled else None
    oip_grpc.add_GRPCInferenceServiceServicer_to_server(
        InferenceServicer(slot, config, batchers, registry), server)


PARTS = ServiceParts(
    SERVICES["models"],
    config_schema=ModelsConfig,
    create_model=create_model,
    add_servicer=add_servicer,
)
