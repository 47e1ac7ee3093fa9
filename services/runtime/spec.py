"""How a service plugs into the runtime: one ServiceSpec per service."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import grpc

from oricf.services.runtime.config import ServiceConfig
from oricf.services.runtime.model import Model, ModelSlot
from oricf.store import ModelStore


@dataclass(frozen=True)
class ServiceSpec:
    name: str                                  # "detector": the CLI and config name
    service_name: str                          # "oricf.v1.Detector": for health and reflection
    config_schema: type[ServiceConfig]
    create_model: Callable[[Any, ModelStore], Model]  # (its config, the store) -> unloaded model
    add_servicer: Callable[[grpc.Server, ModelSlot[Any], Any], None]
    # (slot, its config) -> Starlette routes of the OpenAI-compatible HTTP API; None: none.
    # Called only when server.http is set, so Starlette is imported only then.
    http_routes: Callable[[ModelSlot[Any], Any], list[Any]] | None = None
