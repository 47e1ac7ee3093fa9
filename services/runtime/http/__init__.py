"""The OpenAI-compatible HTTP API of a service, beside its gRPC port, on the same model.

One place for what every service's HTTP side shares: the app factory (app.py), the guards
every request passes (guards.py: error shape, tokens, body limits, the call limit shared
with gRPC), its metrics (metrics.py), helpers for routes (calls.py) and uvicorn in a thread
with TLS (server.py). Each service brings only its routes (its ServiceParts' http_routes).
Imported only when `server.http` is set, so a service without it never loads Starlette.
"""

from __future__ import annotations

from typing import Any

from prometheus_client import CollectorRegistry

from oricf.errors import ConfigError
from oricf.services import SERVICES
from oricf.services.runtime.config import ServiceConfig
from oricf.services.runtime.http.app import build_app
from oricf.services.runtime.http.server import HttpServer
from oricf.services.runtime.limits import CallLimit
from oricf.services.runtime.model import ModelSlot
from oricf.services.runtime.parts import ServiceParts

__all__ = ["HttpServer", "build_app", "http_server"]


def http_server(spec: ServiceParts, slot: ModelSlot[Any], config: ServiceConfig,
                limit: CallLimit, registry: CollectorRegistry | None,
                draining: Any) -> HttpServer:
    """The service's HTTP server, bound and not yet started."""
    settings = config.server
    assert settings.http is not None
    if spec.http_routes is None:
        having = ", ".join(name for name, other in SERVICES.items() if other.http)
        raise ConfigError(f"server.http: the {spec.name} service has no HTTP API (these "
                          f"have one: {having})")
    routes = spec.http_routes(slot, config)
    app = build_app(routes, slot, settings, limit, registry, draining)
    return HttpServer(app, settings.http, settings.tls, settings.grace_s, spec.name)
