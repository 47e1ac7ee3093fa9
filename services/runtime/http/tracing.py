"""A span per request of a service's HTTP API (docs/tracing.md), as a child of the caller's
span when its headers carry a W3C `traceparent` (the gateway's `protocol: openai` endpoints
send one while tracing is on), as the gRPC side does (oricf.services.runtime.tracing).

Plain ASGI middleware, outermost but for the metrics: refusals get a span too, and a
streamed answer's span ends with its last byte. Health checks get none. Installed only while
tracing is on.
"""

from __future__ import annotations

from typing import Any

from opentelemetry.trace import SpanKind, Status, StatusCode

from oricf import tracing
from oricf.services.runtime.http.guards import HEALTH_PATH, Receive, Scope, Send


class TraceMiddleware:
    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope.get("path") == HEALTH_PATH:
            await self.app(scope, receive, send)
            return
        carrier = [(key.decode("latin-1"), value.decode("latin-1"))
                   for key, value in scope.get("headers", ())]
        method, path = scope.get("method", ""), scope.get("path", "")
        answered: list[int] = []

        async def noting_status(message: Any) -> None:
            if message["type"] == "http.response.start":
                answered.append(int(message["status"]))
            await send(message)

        with tracing.tracer().start_as_current_span(
                f"{method} {path}", context=tracing.extract(carrier), kind=SpanKind.SERVER,
                attributes={"http.request.method": method, "url.path": path},
                record_exception=False, set_status_on_exception=False) as span:
            try:
                await self.app(scope, receive, noting_status)
            finally:
                status = answered[0] if answered else 500
                span.set_attribute("http.response.status_code", status)
                if status >= 500:
                    span.set_status(Status(StatusCode.ERROR, f"HTTP {status}"))
