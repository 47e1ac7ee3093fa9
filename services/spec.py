"""What the command line, the launcher and the deployment files know of a model service.

A `ServiceSpec` is read without importing the service: `oricf --help` and a deployment's
validation load no gRPC servicer and no model library. The service's code is named by
convention, `oricf.services.NAME.service`, whose `SERVICE` (a `Service` class) or `PARTS`
(a `ServiceParts`) the runtime serves.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from oricf.config import shipped_service_config


@dataclass(frozen=True)
class ServiceSpec:
    name: str          # `oricf serve NAME`, configs/services/NAME.yaml, a deployment's key
    grpc_service: str  # its gRPC service in the protos: its name for health and reflection
    port: int          # where its shipped config listens (compose and the pipelines agree)
    http: bool = False  # it also serves the OpenAI-compatible HTTP API (--http-listen)

    @property
    def config(self) -> Path:
        """Its shipped YAML: what `oricf serve NAME` reads without --config."""
        return shipped_service_config(self.name)

    @property
    def module(self) -> str:
        """The module whose `SERVICE` class (or `PARTS`) the runtime serves."""
        return f"oricf.services.{self.name}.service"
