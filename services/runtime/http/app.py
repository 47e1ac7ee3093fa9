"""The ASGI app of a service's HTTP API: the service's routes, /health, and the guards and
metrics every route shares (guards.py, metrics.py)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from prometheus_client import CollectorRegistry
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import BaseRoute, Route

from oricf.services.runtime.config import ServerSettings
from oricf.services.runtime.http.errors import ApiError, error_body, error_response
from oricf.services.runtime.http.guards import (
    HEALTH_PATH,
    BodyLimit,
    CallSlot,
    ErrorShape,
    TokenAuth,
)
from oricf.services.runtime.http.metrics import HttpMetrics, MetricsMiddleware
from oricf.services.runtime.http.tracing import TraceMiddleware
from oricf.services.runtime.limits import CallLimit
from oricf.services.runtime.model import ModelSlot
from oricf.tracing import active as tracing_active


def _health(slot: ModelSlot[Any], draining: Callable[[], bool]) -> Route:
    async def health(request: Request) -> Response:
        if draining():
            return JSONResponse(error_body(503, "the service is shutting down"), 503)
        if not slot.ready:
            return JSONResponse(error_body(503, "the model is still loading"), 503)
        return JSONResponse({"status": "SERVING"})

    return Route(HEALTH_PATH, health, methods=["GET"])


def models_route(name: str) -> Route:
    """GET /v1/models: the one model a service serves, as OpenAI lists models."""
    listing = {"object": "list", "data": [
        {"id": name, "object": "model", "created": int(time.time()), "owned_by": "oricf"}]}

    async def models(request: Request) -> Response:
        return JSONResponse(listing)

    return Route("/v1/models", models, methods=["GET"])


def check_model(requested: str | None, served: str) -> None:
    """A request naming another model than the one served: 404 model_not_found."""
    if requested and requested != served:
        raise ApiError(404, f"model '{requested[:80]}' is not served here; this service "
                            f"serves '{served}' (GET /v1/models)",
                       param="model", code="model_not_found")


async def _http_error(request: Request, exc: Exception) -> Response:
    """Starlette's own refusals (unknown path 404, wrong method 405) in OpenAI's shape."""
    assert isinstance(exc, HTTPException)
    message = {404: f"no route {request.url.path}",
               405: f"{request.method} is not allowed on {request.url.path}"}
    return error_response(ApiError(exc.status_code,
                                   message.get(exc.status_code, str(exc.detail))))


def build_app(routes: Sequence[BaseRoute], slot: ModelSlot[Any], server: ServerSettings,
              limit: CallLimit, registry: CollectorRegistry | None,
              draining: Callable[[], bool]) -> Starlette:
    http = server.http
    assert http is not None
    all_routes = [*routes, _health(slot, draining)]
    middleware: list[Middleware] = []
    if registry is not None:
        paths = [route.path for route in all_routes if isinstance(route, Route)]
        middleware.append(Middleware(MetricsMiddleware, metrics=HttpMetrics(registry),
                                     routes=paths))
    if tracing_active():  # a span per request (docs/tracing.md)
        middleware.append(Middleware(TraceMiddleware))
    middleware.append(Middleware(ErrorShape, limit=limit))
    if server.auth is not None:
        middleware.append(Middleware(TokenAuth, tokens=server.auth.tokens()))
    middleware.append(Middleware(BodyLimit, max_body=http.max_body_bytes,
                                 max_upload=http.max_upload_bytes,
                                 timeout_s=http.request_timeout_s))
    middleware.append(Middleware(CallSlot, limit=limit))
    return Starlette(routes=all_routes, middleware=middleware,
                     exception_handlers={HTTPException: _http_error})
