"""Prometheus metrics of a model service: every call by method and status code, how long it
took, the calls in progress against the service's limit, and the model's load.

The call metrics keep the names and labels of grpc-ecosystem's go-grpc-prometheus (also used
by java- and py-grpc-prometheus), so dashboards and alerts written for gRPC servers work as
they are: grpc_server_started_total, grpc_server_handled_total (with grpc_code),
grpc_server_msg_received_total, grpc_server_msg_sent_total and the histogram
grpc_server_handling_seconds, labelled grpc_type, grpc_service and grpc_method. grpc_code is
the status code's name as gRPC's spec and grpcio spell it (OK, INVALID_ARGUMENT).

The interceptor is the outermost one, so it sees each call's final status: a refused token
(UNAUTHENTICATED), a call over the limit (RESOURCE_EXHAUSTED), a mapped error. Those are
raised through context.abort(), which leaves the code on the context; a caller that went
away is CANCELLED (DEADLINE_EXCEEDED if its deadline passed). Only the server's own methods
reach an interceptor's handler (grpc answers unknown ones UNIMPLEMENTED itself), so the label
values stay bounded.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import grpc
from prometheus_client import CollectorRegistry, Counter, Histogram
from prometheus_client.metrics_core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector

from oricf.metrics import LATENCY_BUCKETS_S, new_registry
from oricf.services.runtime.errors import streams_by_callback
from oricf.services.runtime.limits import CallLimit
from oricf.services.runtime.model import ModelSlot

# The handler attribute -> go-grpc-prometheus' grpc_type.
# Upper bounds of the oricf_batch_size buckets (requests per batch).
BATCH_SIZE_BUCKETS = (1, 2, 4, 8, 16, 32, 64, 128, 256)
RPC_TYPES = {"unary_unary": "unary", "unary_stream": "server_stream",
             "stream_unary": "client_stream", "stream_stream": "bidi_stream"}
CALL_LABELS = ("grpc_type", "grpc_service", "grpc_method")


def final_status(context: grpc.ServicerContext, exc: BaseException | None) -> grpc.StatusCode:
    """The status a call ended with, as its caller sees it."""
    # A status is only sent once the handler returns: past the deadline, or with the caller
    # gone, what the handler made of it (such as an error for a request stream cut short)
    # never reached the caller. The deadline is checked first because a request stream cut
    # by it may end before grpcio has marked the call inactive.
    remaining = context.time_remaining()
    if remaining is not None and remaining <= 0:
        return grpc.StatusCode.DEADLINE_EXCEEDED
    if isinstance(exc, GeneratorExit) or not context.is_active():
        return grpc.StatusCode.CANCELLED
    code = context.code()  # set by context.abort() or set_code()
    if code is not None:
        return code  # type: ignore[no-any-return]
    # grpcio answers an exception that escapes a handler with UNKNOWN.
    return grpc.StatusCode.OK if exc is None else grpc.StatusCode.UNKNOWN


class _Call:
    """One call's series, looked up once."""

    def __init__(self, metrics: CallMetrics, labels: tuple[str, str, str]) -> None:
        self._metrics, self._labels = metrics, labels
        self._started = time.perf_counter()
        metrics.started.labels(*labels).inc()
        self.received = metrics.received.labels(*labels).inc
        self.sent = metrics.sent.labels(*labels).inc

    def done(self, code: grpc.StatusCode) -> None:
        self._metrics.handled.labels(*self._labels, code.name).inc()
        self._metrics.seconds.labels(*self._labels).observe(time.perf_counter() - self._started)


def _counted(requests: Iterable[Any], received: Callable[[], None]) -> Iterator[Any]:
    for request in requests:
        received()
        yield request


def _unary_response(behavior: Callable[..., Any], start: Callable[[], _Call],
                    stream: bool) -> Callable[..., Any]:
    def handler(request: Any, context: grpc.ServicerContext) -> Any:
        call = start()
        if stream:
            request = _counted(request, call.received)
        else:
            call.received()
        try:
            response = behavior(request, context)
        except BaseException as exc:
            call.done(final_status(context, exc))
            raise
        code = final_status(context, None)
        if code == grpc.StatusCode.OK:
            call.sent()
        call.done(code)
        return response

    return handler


def _stream_response(behavior: Callable[..., Any], start: Callable[[], _Call],
                     stream: bool) -> Callable[..., Iterator[Any]]:
    def handler(request: Any, context: grpc.ServicerContext) -> Iterator[Any]:
        call = start()
        if stream:
            request = _counted(request, call.received)
        else:
            call.received()
        try:
            for response in behavior(request, context):
                call.sent()
                yield response
        except BaseException as exc:  # GeneratorExit too: the caller went away mid-stream
            call.done(final_status(context, exc))
            raise
        call.done(final_status(context, None))

    return handler


def _callback_stream(behavior: Callable[..., Any], start: Callable[[], _Call]
                     ) -> Callable[..., None]:
    """A handler that streams through a callback (health's Watch): counted like the others
    while still holding no thread for the life of its stream."""
    def handler(request: Any, context: grpc.ServicerContext,
                send_response_callback: Callable[[Any], None]) -> None:
        call = start()
        call.received()
        ended = threading.Event()

        def send(response: Any) -> None:
            if response is not None:
                call.sent()
            elif not ended.is_set():  # None ends the stream
                ended.set()
                call.done(final_status(context, None))
            send_response_callback(response)

        try:
            behavior(request, context, send)
        except BaseException as exc:
            if not ended.is_set():
                ended.set()
                call.done(final_status(context, exc))
            raise

    handler.experimental_non_blocking = True  # type: ignore[attr-defined]
    return handler


class CallMetrics(grpc.ServerInterceptor):
    """Counts and times every call of the server it is installed on (first in the list)."""

    def __init__(self, registry: CollectorRegistry) -> None:
        self.started = Counter("grpc_server_started", "RPCs started on the server.",
                               CALL_LABELS, registry=registry)
        self.handled = Counter(
            "grpc_server_handled",
            "RPCs completed on the server, regardless of success or failure.",
            (*CALL_LABELS, "grpc_code"), registry=registry)
        self.received = Counter("grpc_server_msg_received",
                                "Request messages received on the server.", CALL_LABELS,
                                registry=registry)
        self.sent = Counter("grpc_server_msg_sent", "Response messages sent by the server.",
                            CALL_LABELS, registry=registry)
        self.seconds = Histogram(
            "grpc_server_handling_seconds",
            "Time from the start of an RPC to its end on the server (a whole stream).",
            CALL_LABELS, buckets=LATENCY_BUCKETS_S, registry=registry)

    def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], grpc.RpcMethodHandler | None],
        handler_call_details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler | None:
        handler = continuation(handler_call_details)
        if handler is None:
            return None
        service, _, method = handler_call_details.method.lstrip("/").rpartition("/")
        kind = next(k for k in RPC_TYPES if getattr(handler, k) is not None)
        labels = (RPC_TYPES[kind], service, method)

        def start() -> _Call:
            return _Call(self, labels)

        behavior = getattr(handler, kind)
        if streams_by_callback(handler):
            return handler._replace(unary_stream=_callback_stream(behavior, start))
        stream = kind.startswith("stream")
        wrap = _stream_response if kind.endswith("_stream") else _unary_response
        return handler._replace(**{kind: wrap(behavior, start, stream)})


class ServiceCollector(Collector):
    """The model's load and the call limit, read from the runtime at scrape time."""

    def __init__(self, service: str, slot: ModelSlot[Any], limit: CallLimit) -> None:
        self._service = service
        self._slot = slot
        self._limit = limit
        self._model = slot.peek().info().model  # from its config: known before the load

    def collect(self) -> Iterable[Metric]:
        model = (("service", "model"), (self._service, self._model))
        service = (("service",), (self._service,))
        yield _gauge("oricf_model_ready", "1 while the model is loaded and the service SERVING.",
                     *model, 1.0 if self._slot.ready else 0.0)
        if self._slot.load_seconds > 0:  # absent until loaded, rather than a false 0
            yield _gauge("oricf_model_load_seconds",
                         "How long loading and warming up the model took.",
                         *model, self._slot.load_seconds)
            info = self._slot.peek().info()
            yield _gauge("oricf_model_info", "Where the loaded model runs: its runtime and the "
                         "execution provider or device that runs it (the first in use).",
                         ("service", "model", "runtime", "provider"),
                         (self._service, self._model, info.runtime,
                          info.providers[0] if info.providers else ""), 1.0)
        yield _gauge("oricf_service_calls_in_progress",
                     "Calls running now that count against the limit (health and reflection "
                     "do not).", *service, self._limit.active)
        yield _gauge("oricf_service_calls_limit",
                     "server.max_concurrent_rpcs: calls beyond it are refused "
                     "RESOURCE_EXHAUSTED.", *service, self._limit.limit)
        if self._slot.batchers:
            yield from self._batching()

    def _batching(self) -> Iterable[Metric]:
        labels = ("service", "batcher")
        sizes = HistogramMetricFamily(
            "oricf_batch_size", "Requests run together in one inference (dynamic batching).",
            labels=labels)
        queued = GaugeMetricFamily("oricf_batch_queue_length",
                                   "Requests waiting for a batch.", labels=labels)
        dropped = CounterMetricFamily(
            "oricf_batch_dropped", "Requests that never reached a batch: deadline (passed "
            "while queued), cancelled (the caller went away), refused (the queue was full).",
            labels=(*labels, "reason"))
        for batcher in self._slot.batchers:
            values = (self._service, batcher.name)
            counts, drops, waiting = batcher.snapshot()
            buckets = [(str(float(bound)),
                        float(sum(n for size, n in counts.items() if size <= bound)))
                       for bound in BATCH_SIZE_BUCKETS]
            buckets.append(("+Inf", float(sum(counts.values()))))
            sizes.add_metric(values, buckets,
                             float(sum(size * n for size, n in counts.items())))
            queued.add_metric(values, waiting)
            for reason in ("deadline", "cancelled", "refused"):
                dropped.add_metric((*values, reason), drops.get(reason, 0))
        yield from (sizes, queued, dropped)


def _gauge(name: str, documentation: str, labels: tuple[str, ...], values: tuple[str, ...],
           value: float) -> GaugeMetricFamily:
    """A gauge family holding one sample."""
    family = GaugeMetricFamily(name, documentation, labels=labels)
    family.add_metric(values, value)
    return family


def service_registry(service: str, slot: ModelSlot[Any],
                     limit: CallLimit) -> tuple[CollectorRegistry, CallMetrics]:
    """A registry of its own for one service, and the interceptor that feeds it."""
    registry = new_registry()
    calls = CallMetrics(registry)
    registry.register(ServiceCollector(service, slot, limit))
    return registry, calls
