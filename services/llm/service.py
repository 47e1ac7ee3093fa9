"""The language model as a runtime service: `oricf serve llm`."""

from __future__ import annotations

from typing import Any

import grpc

from oricf.services import SERVICES
from oricf.services.llm.config import LlmConfig, load_prompt
from oricf.services.llm.decode import Sampling
from oricf.services.llm.model import LlamaModel, LlamaSettings
from oricf.services.llm.servicer import LanguageModelServicer
from oricf.services.runtime import ModelSlot, ServiceParts
from oricf.store import ModelStore
from oricf.v1 import language_pb2_grpc


def create_model(config: LlmConfig, store: ModelStore) -> LlamaModel:
    name = config.model.name
    entry = store.entry(name)
    path = store.path(name, "model.gguf")
    g = config.generation
    return LlamaModel(LlamaSettings(
        path=path, catalog_name=name, sha256=entry.files[0].sha256, license=entry.license,
        template=load_prompt(config.prompt_path), prompt_file=config.prompt_path.name,
        n_ctx=config.model.n_ctx, n_batch=config.model.n_batch, threads=config.model.threads,
        omp_wait_policy=config.model.omp_wait_policy, reuse_prefix=config.model.reuse_prefix,
        gpu_layers=config.model.gpu_layers,
        sampling=Sampling(temperature=g.temperature, top_k=g.top_k, top_p=g.top_p,
                          min_p=g.min_p, repeat_penalty=g.repeat_penalty),
        max_waiting=config.queue.max_waiting, wait_timeout_s=config.queue.wait_timeout_s))


def add_servicer(server: grpc.Server, slot: ModelSlot[LlamaModel], config: LlmConfig) -> None:
    language_pb2_grpc.add_LanguageModelServicer_to_server(
        LanguageModelServicer(slot, config), server)


def http_routes(slot: ModelSlot[LlamaModel], config: LlmConfig) -> list[Any]:
    """OpenAI's chat completions API (docs/openai.md); Starlette is imported only here."""
    from oricf.services.llm.openai_api import routes

    return routes(slot, config)


PARTS = ServiceParts(
    SERVICES["llm"],
    config_schema=LlmConfig,
    create_model=create_model,
    add_servicer=add_servicer,
    http_routes=http_routes,
)
