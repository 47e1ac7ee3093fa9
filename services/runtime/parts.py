"""How a service plugs into the runtime: its `ServiceParts` (config schema, model, servicer,
HTTP routes), served under the name and gRPC service of its `ServiceSpec`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import grpc

from oricf.services.runtime.config import ServiceConfig
from oricf.services.runtime.model import Model, ModelSlot
from oricf.services.runtime.streams import MessageStreams
from oricf.services.spec import ServiceSpec
from oricf.store import ModelStore


@dataclass(frozen=True)
class ServiceParts:
    spec: ServiceSpec                          # its entry in oricf.services.SERVICES
    config_schema: type[ServiceConfig]
    create_model: Callable[[Any, ModelStore], Model]  # (its config, the store) -> unloaded model
    add_servicer: Callable[[grpc.Server, ModelSlot[Any], Any], None]
    # (slot, its config) -> Starlette routes of the OpenAI-compatible HTTP API; None: none.
    # Called only when server.http is set, so Starlette is imported only then.
    http_routes: Callable[[ModelSlot[Any], Any], list[Any]] | None = None
    # its config -> the streaming RPCs answered message by message (runtime/streams.py);
    # None: a stream holds a call slot for as long as it is open.
    message_streams: Callable[[Any], MessageStreams] | None = None

    @property
    def name(self) -> str:
        """"detector": the CLI and config name, and its metrics' and logs' label."""
        return self.spec.name

    @property
    def service_name(self) -> str:
        """"oricf.v1.Detector": for health and reflection."""
        return self.spec.grpc_service
