"""Prometheus metrics of the HTTP API, in the service's own registry beside the gRPC ones.

The names and labels follow OpenTelemetry's HTTP server conventions as Prometheus spells
them: http_server_request_duration_seconds (a histogram whose _count is the requests),
labelled http_request_method, http_route and http_response_status_code, and
http_server_active_requests. http_route is the route's path for the service's own routes
and "other" for anything else, so a scan of random paths cannot grow the label values.
The middleware is the outermost, so it sees refusals (401, 413, 429) too.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Any

from prometheus_client import CollectorRegistry, Gauge, Histogram

from oricf.metrics import LATENCY_BUCKETS_S
from oricf.services.runtime.http.errors import CLIENT_CLOSED

OTHER_ROUTE = "other"
METHODS = {"GET", "POST", "HEAD", "OPTIONS", "PUT", "DELETE", "PATCH"}


class HttpMetrics:
    """The metric families; one per registry."""

    def __init__(self, registry: CollectorRegistry) -> None:
        self.seconds = Histogram(
            "http_server_request_duration_seconds",
            "HTTP requests: from the request's headers to the end of its answer (a whole "
            "stream).", ("http_request_method", "http_route", "http_response_status_code"),
            buckets=LATENCY_BUCKETS_S, registry=registry)
        self.active = Gauge("http_server_active_requests", "HTTP requests being answered.",
                            ("http_request_method", "http_route"), registry=registry)


class MetricsMiddleware:
    def __init__(self, app: Any, metrics: HttpMetrics, routes: Iterable[str]) -> None:
        self.app = app
        self.metrics = metrics
        self.routes = frozenset(routes)

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        method = scope["method"] if scope["method"] in METHODS else "_OTHER"
        route = scope["path"] if scope["path"] in self.routes else OTHER_ROUTE
        status = CLIENT_CLOSED  # unless an answer starts

        async def watched_send(message: Any) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        started = time.perf_counter()
        active = self.metrics.active.labels(method, route)
        active.inc()
        try:
            await self.app(scope, receive, watched_send)
        finally:
            active.dec()
            self.metrics.seconds.labels(method, route, str(status)).observe(
                time.perf_counter() - started)
