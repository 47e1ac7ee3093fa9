"""A span per call of a service (docs/tracing.md), as a child of the caller's span when the
call's metadata carries a W3C `traceparent` (the gateway sends one while tracing is on).

The span is current while the servicer runs, so a servicer's own spans (the detector's
decode, preprocess, inference and postprocess) are its children. Health checks and
reflection get none. Installed only while tracing is on (oricf.tracing.active).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import grpc
from opentelemetry import trace
from opentelemetry.trace import SpanKind, Status, StatusCode

from oricf import tracing

UNTRACED_PREFIXES = ("/grpc.health.v1.", "/grpc.reflection.")


@contextmanager
def _call_span(method: str, metadata: Any, context: grpc.ServicerContext) -> Iterator[None]:
    service, _, rpc = method.lstrip("/").partition("/")
    with tracing.tracer().start_as_current_span(
            f"{service}/{rpc}", context=tracing.extract(metadata), kind=SpanKind.SERVER,
            attributes={"rpc.system": "grpc", "rpc.service": service, "rpc.method": rpc},
            record_exception=False, set_status_on_exception=False) as span:
        try:
            yield
        finally:
            _set_status(span, context)


def _set_status(span: trace.Span, context: grpc.ServicerContext) -> None:
    """The call's gRPC status on the span (an abort raises past it with no message)."""
    code = getattr(context, "code", lambda: None)()
    if code is None or code == grpc.StatusCode.OK:
        span.set_attribute("rpc.grpc.status_code", 0)
        return
    span.set_attribute("rpc.grpc.status_code", code.value[0])
    span.set_status(Status(StatusCode.ERROR, code.name))


def _unary(behavior: Callable[..., Any], method: str, metadata: Any) -> Callable[..., Any]:
    def handler(request: Any, context: grpc.ServicerContext) -> Any:
        with _call_span(method, metadata, context):
            return behavior(request, context)

    return handler


def _stream(behavior: Callable[..., Any], method: str, metadata: Any) -> Callable[..., Any]:
    def handler(request: Any, context: grpc.ServicerContext) -> Iterator[Any]:
        with _call_span(method, metadata, context):
            yield from behavior(request, context)

    return handler


class TracingInterceptor(grpc.ServerInterceptor):
    def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], grpc.RpcMethodHandler | None],
        details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler | None:
        handler = continuation(details)
        method = details.method
        if handler is None or method.startswith(UNTRACED_PREFIXES):
            return handler
        metadata = details.invocation_metadata
        if handler.unary_unary:
            return handler._replace(unary_unary=_unary(handler.unary_unary, method, metadata))
        if handler.stream_unary:
            return handler._replace(stream_unary=_unary(handler.stream_unary, method, metadata))
        if handler.unary_stream:
            return handler._replace(unary_stream=_stream(handler.unary_stream, method, metadata))
        if handler.stream_stream:
            return handler._replace(stream_stream=_stream(handler.stream_stream, method,
                                                          metadata))
        return handler


def spans_ending_now(steps: list[tuple[str, float]]) -> None:
    """Child spans of the current one for steps a model timed itself (name, milliseconds),
    one after the other, the last ending now: where the steps ran inside one call (a batch's
    inference, its decoding) and only their durations are known."""
    if not tracing.active():
        return
    end = time.time_ns()
    start = end - int(sum(ms for _, ms in steps) * 1e6)
    for name, ms in steps:
        finish = start + int(ms * 1e6)
        tracing.tracer().start_span(name, start_time=start).end(end_time=finish)
        start = finish
