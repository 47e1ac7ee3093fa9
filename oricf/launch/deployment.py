"""Deployment YAML (configs/deployments/*.yaml): which services and gateway run where.

A deployment names the model services started on this machine (`services`), the services
used on another machine (`remote`, e.g. an edge server running compose/edge.yaml), and the
gateway. The gateway is told every service address through a generated overlay, so the
pipeline YAML itself never changes with placement.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator, model_validator

from oricf.config import FilePath, Schema, check_address, load_config, shipped_service_config
from oricf.errors import ConfigError
from oricf.tls import ClientTls

# the keys of oricf.services.REGISTRY (a test keeps the two in step)
ServiceName = Literal["detector", "asr", "llm", "models"]


class Restart(Schema):
    policy: Literal["no", "on-failure", "always"] = Field(
        "on-failure", description="restart after a crash (non-zero exit) or after any exit")
    max_restarts: int = Field(3, ge=0, le=1000, description="restarts allowed in total")
    delay_s: float = Field(1.0, ge=0, le=300, description="pause before a restart")


class LocalService(Schema):
    config: FilePath | None = Field(None, description="default: configs/services/NAME.yaml")
    listen: str | None = Field(None, description="host:port; default: the config's server.listen")
    env: dict[str, str] = Field(default_factory=dict, description="extra environment")
    restart: Restart = Restart()

    @field_validator("listen")
    @classmethod
    def _listen(cls, value: str | None) -> str | None:
        return value if value is None else check_address(value)


class RemoteService(Schema):
    address: str = Field(description="host:port of a service started elsewhere")
    wait: bool = Field(True, description="wait for it to be SERVING before starting the gateway")

    @field_validator("address")
    @classmethod
    def _address(cls, value: str) -> str:
        return check_address(value)


class Gateway(Schema):
    config: FilePath = Field(description="pipeline YAML, e.g. ../pipelines/people_qa.yaml")
    overlays: list[FilePath] = Field(default_factory=list, description="merged in order")
    profile: str | None = Field(None, description="a named entry of the pipeline's profiles")
    env: dict[str, str] = Field(default_factory=dict)
    restart: Restart = Restart()


class Deployment(Schema):
    description: str = ""
    services: dict[ServiceName, LocalService] = Field(default_factory=dict)
    remote: dict[ServiceName, RemoteService] = Field(default_factory=dict)
    gateway: Gateway | None = None
    env: dict[str, str] = Field(default_factory=dict, description="for every process")
    startup_timeout_s: float = Field(600, gt=0, description="per service, to reach SERVING")
    tls: ClientTls | None = Field(
        None, description="how the health checks reach services that serve TLS (CA, and a "
                          "client certificate where they require one)")
    stop_grace_s: float = Field(10, ge=0, le=600, description="SIGTERM to SIGKILL")

    @model_validator(mode="after")
    def _placement(self) -> Deployment:
        both = sorted(set(self.services) & set(self.remote))
        if both:
            raise ValueError(f"{', '.join(both)}: both in services and in remote")
        if not self.services and self.gateway is None:
            raise ValueError("nothing to run: give services, a gateway, or both")
        return self


@dataclass(frozen=True)
class ProcessPlan:
    """One process to start: its command, environment, restart policy and health address."""

    name: str
    argv: list[str]
    env: dict[str, str]
    restart: Restart
    health: str | None = None  # host:port to ask grpc.health.v1, None for the gateway
    endpoints: dict[str, str] = field(default_factory=dict)


def load_deployment(path: Path | str) -> Deployment:
    return load_config(path, Deployment)


def connect_address(listen: str) -> str:
    """Where a client on this machine reaches a server listening on `listen`."""
    host, _, port = listen.rpartition(":")
    if host in ("0.0.0.0", "[::]", "::", ""):
        host = "127.0.0.1"
    return f"{host}:{port}"


def service_config_path(name: str, entry: LocalService) -> Path:
    return entry.config or shipped_service_config(name)


def service_plan(name: str, entry: LocalService, deployment: Deployment) -> ProcessPlan:
    """The `oricf serve` command of one service; its config is validated here, before start."""
    from oricf.services import load_spec

    path = service_config_path(name, entry)
    config = load_config(path, load_spec(name).config_schema)
    listen = entry.listen or config.server.listen
    port = listen.rpartition(":")[2]
    if port == "0":
        raise ConfigError(f"{path}: server.listen: port 0 cannot be used in a deployment")
    argv = [sys.executable, "-m", "oricf", "serve", name, "--config", str(path),
            "--listen", listen]
    return ProcessPlan(name, argv, {**deployment.env, **entry.env}, entry.restart,
                       health=connect_address(listen))


def endpoint_addresses(deployment: Deployment, plans: list[ProcessPlan]) -> dict[str, str]:
    """Service name -> address the gateway should call, for every service the deployment knows."""
    addresses = {plan.name: plan.health for plan in plans if plan.health}
    addresses.update({name: remote.address for name, remote in deployment.remote.items()})
    return addresses


def gateway_plan(deployment: Deployment, endpoints_overlay: Path) -> ProcessPlan:
    gateway = deployment.gateway
    assert gateway is not None
    argv = [sys.executable, "-m", "oricf", "gateway", "--config", str(gateway.config)]
    for overlay in [*gateway.overlays, endpoints_overlay]:
        argv += ["--overlay", str(overlay)]
    if gateway.profile:
        argv += ["--profile", gateway.profile]
    return ProcessPlan("gateway", argv, {**deployment.env, **gateway.env}, gateway.restart)

