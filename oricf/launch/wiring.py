"""How a deployment's gateway reaches the model services.

Placement is said in one place: the gateway's pipeline and its overlays
(configs/pipelines/placement/) give every endpoint's address, fallback, deadline, image
transport and TLS. A deployment adds only what it decides itself: where the services it
starts listen. Each started service is wired into the endpoint of its name, at the one
address of that endpoint that is on this machine:

- an address or fallback that is exactly where the service listens: nothing to change;
- else the one of them on this machine (a loopback host, or the service's own host): that
  one moves to the service's port. With detector on the edge and an onboard fallback
  (placement/edge.yaml), the fallback becomes the detector started here; the edge stays.

An endpoint with neither address on this machine would never call the service started
here, and one with both there (and neither exact) leaves no way to tell which is meant:
both are refused. Endpoints in `remote` are waited for at their pipeline address, with
their pipeline TLS.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from oricf.errors import ConfigError
from oricf.hosts import Address, host_of, is_loopback_address
from oricf.launch.deployment import Deployment

if TYPE_CHECKING:
    from oricf.gateway.config import PipelineConfig
    from oricf.gateway.endpoints import EndpointConfig

log = logging.getLogger(__name__)

SLOTS = ("address", "fallback")


@dataclass(frozen=True)
class Wiring:
    """What the launcher adds to the gateway, and what it waits for."""

    endpoints: dict[str, dict[str, Any]]  # the overlay's endpoints: name -> {slot: address}
    remote: dict[str, EndpointConfig]  # endpoints to find SERVING before the gateway starts


def gateway_pipeline(deployment: Deployment) -> tuple[PipelineConfig, str]:
    """The gateway's pipeline with its overlays merged, and the names of those files."""
    from oricf.gateway.config import load_pipeline

    gateway = deployment.gateway
    assert gateway is not None
    sources = " + ".join(str(p) for p in [gateway.config, *gateway.overlays])
    return load_pipeline(gateway.config, gateway.overlays), sources


def wire_gateway(deployment: Deployment, started: dict[str, str]) -> Wiring:
    """started: service name -> the address it listens at, as this machine reaches it."""
    pipeline, sources = gateway_pipeline(deployment)
    endpoints: dict[str, dict[str, Any]] = {}
    for name, address in started.items():
        endpoint = pipeline.endpoints.get(name)
        if endpoint is None:
            continue  # the gateway does not call it
        slot = _slot(deployment, sources, name, endpoint, address)
        said = endpoint.targets[slot].address
        if said != address:
            log.info("gateway: endpoint %s %s %s (the %s started here; the pipeline says %s)",
                     name, slot, address, name, said)
            # A fallback of its own (a mapping) keeps its protocol: only its address moves.
            own = slot == "fallback" and not isinstance(endpoint.fallback, str)
            endpoints[name] = {slot: {"address": address} if own else address}
    remote = {}
    for i, name in enumerate(deployment.remote):
        if name not in pipeline.endpoints:
            raise ConfigError(f"{deployment.source}: remote[{i}]: the gateway's pipeline has "
                              f"no endpoint '{name}' ({sources}; endpoints: "
                              f"{', '.join(sorted(pipeline.endpoints))})")
        if pipeline.endpoints[name].protocol != "grpc":
            raise ConfigError(f"{deployment.source}: remote[{i}]: the endpoint '{name}' speaks "
                              f"{pipeline.endpoints[name].protocol}; the launcher waits only "
                              f"for gRPC services (grpc.health.v1)")
        remote[name] = pipeline.endpoints[name]
    return Wiring(endpoints, remote)


def _slot(deployment: Deployment, sources: str, name: str, endpoint: EndpointConfig,
          address: str) -> str:
    """The address or fallback of the endpoint that the service started at `address` is."""
    given = {slot: target.address for slot, target in endpoint.targets.items()
             if target.protocol == "grpc"}
    exact = [slot for slot, value in given.items() if value == address]
    if exact:
        return exact[0]
    here = [slot for slot, value in given.items()
            if is_loopback_address(value) or host_of(value) == host_of(address)]
    said = ", ".join(f"{slot} {value}" for slot, value in given.items())
    where = f"{deployment.source}: services.{name}: the gateway's endpoint '{name}' ({said}; " \
            f"{sources})"
    if not here:
        raise ConfigError(f"{where} never calls this machine, so the {name} started here on "
                          f"{address} would not be used: remove it from services, or make "
                          f"it the endpoint's fallback in an overlay (fallback: {address})")
    if len(here) > 1:
        raise ConfigError(f"{where} has both on this machine and neither is {address}, where "
                          f"the {name} started here listens: say which in an overlay")
    return here[0]


def edge_host_endpoints(deployment: Deployment, host: str) -> dict[str, dict[str, str]]:
    """An overlay's endpoints moving every address and fallback that is not on this machine
    to `host` (same port): `oricf demo --edge-host`."""
    pipeline, _ = gateway_pipeline(deployment)
    moved: dict[str, dict[str, str]] = {}
    for name, endpoint in pipeline.endpoints.items():
        for slot, target in endpoint.targets.items():
            value = target.address
            if target.protocol == "grpc" and not is_loopback_address(value):
                moved.setdefault(name, {})[slot] = f"{host}:{Address.parse(value).port}"
    return moved
