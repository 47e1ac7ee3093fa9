"""Deployment YAML (configs/deployments/*.yaml): which services and gateway run where.

A deployment names the model services started on this machine (`services`), the gateway
(its pipeline and overlays), and which of the gateway's endpoints served elsewhere must be
SERVING before it starts (`remote`, e.g. an edge server running compose/edge.yaml). Where
each endpoint is (address, fallback, deadline, transport, TLS) is said once, in the
pipeline and its placement overlays; the deployment only says where the services it starts
listen, and oricf.launch.wiring points the gateway at them.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from pydantic import Field, PrivateAttr, field_validator, model_validator

from oricf.config import FilePath, Schema, load_config
from oricf.errors import ConfigError
from oricf.hosts import Address
from oricf.services import SERVICES, load_spec
from oricf.tls import ClientTls

# A `services:` key: one of SERVICES, a Literal so that a wrong key is refused naming them.
if TYPE_CHECKING:
    ServiceName = str
else:
    ServiceName = Literal[tuple(SERVICES)]


class Restart(Schema):
    policy: Literal["no", "on-failure", "always"] = Field(
        "on-failure", description="restart after a crash (non-zero exit) or after any exit")
    max_restarts: int = Field(3, ge=0, le=1000, description="restarts allowed in total")
    delay_s: float = Field(1.0, ge=0, le=300, description="pause before a restart")


class LocalService(Schema):
    config: FilePath | None = Field(None, description="default: configs/services/NAME.yaml")
    overlays: list[FilePath] = Field(
        default_factory=list, description="merged on top of config in order, e.g. "
                                          "../services/overlays/tls.yaml")
    listen: str | None = Field(None, description="host:port; default: the config's server.listen")
    env: dict[str, str] = Field(default_factory=dict, description="extra environment")
    restart: Restart = Restart()

    @field_validator("listen")
    @classmethod
    def _listen(cls, value: str | None) -> str | None:
        if value is not None:
            Address.parse(value)
        return value


class Gateway(Schema):
    config: FilePath = Field(description="pipeline YAML, e.g. ../pipelines/people_qa.yaml")
    overlays: list[FilePath] = Field(
        default_factory=list, description="merged in order: placement, e.g. "
                                          "../pipelines/placement/edge.yaml")
    env: dict[str, str] = Field(default_factory=dict)
    restart: Restart = Restart()


class Deployment(Schema):
    description: str = ""
    services: dict[ServiceName, LocalService] = Field(default_factory=dict)
    remote: list[str] = Field(
        default_factory=list, description="endpoints of the gateway's pipeline served "
        "elsewhere that must be SERVING before the gateway starts (checked at their address, "
        "with their tls, from the pipeline and its overlays)")
    gateway: Gateway | None = None
    env: dict[str, str] = Field(default_factory=dict, description="for every process")
    startup_timeout_s: float = Field(600, gt=0, description="per service, to reach SERVING")
    tls: ClientTls | None = Field(
        None, description="how the health checks reach services that serve TLS (CA, and a "
                          "client certificate where they require one)")
    stop_grace_s: float = Field(10, ge=0, le=600, description="SIGTERM to SIGKILL")
    _source: str = PrivateAttr("deployment")

    @field_validator("remote", mode="before")
    @classmethod
    def _remote_names(cls, value: Any) -> Any:
        if isinstance(value, dict):
            raise ValueError("a list of the gateway's endpoint names to wait for; their "
                             "addresses come from its pipeline and overlays "
                             "(configs/pipelines/placement/), not from the deployment")
        return value

    @model_validator(mode="after")
    def _placement(self) -> Deployment:
        both = sorted(set(self.services) & set(self.remote))
        if both:
            raise ValueError(f"{', '.join(both)}: both in services and in remote")
        if self.remote and self.gateway is None:
            raise ValueError("remote: only with a gateway (its pipeline says where they are)")
        if not self.services and self.gateway is None:
            raise ValueError("nothing to run: give services, a gateway, or both")
        return self

    @property
    def source(self) -> str:
        """The file it was read from, for messages."""
        return self._source


@dataclass(frozen=True)
class ProcessPlan:
    """One process to start: its command, environment, restart policy and health address."""

    name: str
    argv: list[str]
    env: dict[str, str]
    restart: Restart
    health: str | None = None  # host:port to ask grpc.health.v1, None for the gateway
    reads: tuple[Path, ...] = ()  # its certificate, key, client CA, token file


def load_deployment(path: Path | str) -> Deployment:
    deployment = load_config(path, Deployment)
    deployment._source = str(path)
    return deployment


def connect_address(listen: str) -> str:
    """Where a client on this machine reaches a server listening on `listen`."""
    return str(Address.parse(listen, any_port=True).reached_here())


def service_config_path(name: str, entry: LocalService) -> Path:
    return entry.config or SERVICES[name].config


def service_plan(name: str, entry: LocalService, deployment: Deployment) -> ProcessPlan:
    """The `oricf serve` command of one service; its config is validated here, before start."""
    path = service_config_path(name, entry)
    config = load_config(path, load_spec(name).config_schema, entry.overlays)
    listen = entry.listen or config.server.listen
    try:
        port = Address.parse(listen, any_port=True).port
    except ValueError as exc:
        raise ConfigError(f"{path}: server.listen: {exc}") from None
    if port == 0:
        raise ConfigError(f"{path}: server.listen: port 0 cannot be used in a deployment")
    argv = [sys.executable, "-m", "oricf", "serve", name, "--config", str(path)]
    for overlay in entry.overlays:
        argv += ["--overlay", str(overlay)]
    argv += ["--listen", listen]
    server = config.server
    if server.tls and (deployment.tls is None
                       or (server.tls.client_ca and deployment.tls.cert is None)):
        need = "ca, cert and key" if server.tls.client_ca else "ca"
        raise ConfigError(f"{deployment.source}: tls: {name} serves TLS ({path} + its "
                          f"overlays: server.tls), so the health checks need the "
                          f"deployment's tls: {need}")
    reads = [*((server.tls.cert, server.tls.key, server.tls.client_ca) if server.tls else ()),
             server.auth.file if server.auth else None]
    return ProcessPlan(name, argv, {**deployment.env, **entry.env}, entry.restart,
                       health=connect_address(listen), reads=tuple(p for p in reads if p))


def gateway_plan(deployment: Deployment, wiring_overlay: Path | None) -> ProcessPlan:
    """`oricf gateway` with the deployment's overlays, then the one that points the
    gateway at the services started here (if any endpoint needs it)."""
    gateway = deployment.gateway
    assert gateway is not None
    argv = [sys.executable, "-m", "oricf", "gateway", "--config", str(gateway.config)]
    for overlay in [*gateway.overlays, *([wiring_overlay] if wiring_overlay else [])]:
        argv += ["--overlay", str(overlay)]
    return ProcessPlan("gateway", argv, {**deployment.env, **gateway.env}, gateway.restart)

