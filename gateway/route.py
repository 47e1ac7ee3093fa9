"""A route: input record -> method call -> post steps -> outputs. No ROS in here.

A method whose call streams (a Generate cut into sentences, a Synthesize sentence by
sentence) hands on pieces of its result as they come (`Partial`): each goes at once to the
outputs that take its fields, before post steps (which run on the whole result). A barge-in
(oricf.gateway.speaking) ends such a stream: what it would still say is dropped.

Every failure of one message is logged (throttled, per route and kind of failure) and
counted, and told to whoever asked for the record (the item's asker, oricf.gateway.items:
a text channel's client, which no output will answer now, or a control loop, which asks
again); an item that went through is told its record (a control loop takes its chunk). The
route goes on with the next message. Data
products go to the ProductStore; every other output to the pipeline's emitter
(oricf.gateway.components.Emitter: its outlets, oricf.gateway.outlets.Outlets, send them to
files, text channels, and topics through the ROS node's publishers or a recording). Then each
of the route's watchers (the live view) is shown the record.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Collection, Generator
from dataclasses import dataclass, field
from typing import Any, Protocol

import grpc
from opentelemetry import context as otel_context
from opentelemetry.trace import Status, StatusCode, get_current_span

from oricf.errors import InvalidInput
from oricf.gateway.components import (
    METHODS,
    Emitter,
    MethodCall,
    Partial,
    PostSteps,
    Skip,
    Stream,
    result_fields,
)
from oricf.gateway.config import RouteConfig
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.items import Asker, Loader, asker_of
from oricf.gateway.products import ProductStore
from oricf.gateway.speaking import Speaking
from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.values import Record
from oricf.logs import quoted
from oricf.metrics import LatencyHistogram
from oricf.tracing import active as tracing_active
from oricf.tracing import span

log = logging.getLogger(__name__)

# Call errors whose details are meant for the caller (a client mistake), so they may be told.
TOLD_IN_FULL = {grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.OUT_OF_RANGE,
                grpc.StatusCode.FAILED_PRECONDITION}


class TracedLoader(Asker):
    """A loader with the trace context it was submitted in: a route fed by another's
    product (a transcript, an answer) joins that route's trace. Its asker is the loader's."""

    def __init__(self, load: Loader, context: otel_context.Context) -> None:
        self.load = load
        self.trace_context = context
        self._asker = asker_of(load)

    def __call__(self) -> Record:
        return self.load()

    def answered(self, record: Record) -> None:
        self._asker.answered(record)

    def fail(self, message: str) -> None:
        self._asker.fail(message)

    def on_drop(self, reason: str) -> None:
        self._asker.on_drop(reason)


def with_trace_context(load: Loader) -> Loader:
    """The loader, carrying the current span's context when there is one to carry."""
    if not tracing_active() or not get_current_span().get_span_context().is_valid:
        return load
    return TracedLoader(load, otel_context.get_current())


class Watcher(Protocol):
    """Shown each record a route finished, after its outputs (the live view,
    oricf.gateway.live_view.view.LiveView), in the route's thread: it must not block."""

    def show(self, route: str, record: Record) -> None: ...


@dataclass
class RouteStats:
    ok: int = 0
    skipped: int = 0
    bad_input: int = 0
    call_errors: int = 0
    errors: dict[str, int] = field(default_factory=dict)  # kind -> count
    last_ms: float = 0.0
    latency: LatencyHistogram = field(default_factory=LatencyHistogram)  # inputs handled ok

    def count_error(self, kind: str) -> None:
        self.errors[kind] = self.errors.get(kind, 0) + 1


class Route:
    def __init__(self, name: str, config: RouteConfig, endpoint: Endpoint,
                 products: ProductStore, emitter: Emitter, throttle: ThrottledLog,
                 speaking: Speaking | None = None) -> None:
        self.name = name
        self.config = config
        self.endpoint = endpoint
        self.products = products
        self.stats = RouteStats()
        # (time.monotonic() when done, the record): the newest one that went through, for
        # readers such as the control API's `look` (oricf.gateway.api)
        self.latest: tuple[float, Record] | None = None
        self.watchers: list[Watcher] = []
        self.emitter = emitter
        self.post = PostSteps(config.post)
        self._throttle = throttle
        self._speaking = speaking or Speaking()
        # The method bound to this route, built once (oricf.gateway.components.MethodCall).
        method = METHODS[config.call.method]
        self.method: MethodCall[Any] = method.open(config.call, endpoint, products)

    def run(self, record: Record) -> Record:
        """Call and post-process one record; returns it with every field filled in."""
        record.setdefault("route", self.name)
        asked_at = time.monotonic()
        # Spans of the route's trace (docs/tracing.md): the call carries the trace context
        # to the service; a streamed answer's first piece is an event on the call's span.
        with span(f"call {self.config.call.method}"):
            result = self.method.execute(record)
            if isinstance(result, Generator):
                result = self._stream(record, result, asked_at)
        record.update(result_fields(result))
        with span("post"):
            self.post.run(record)
        return record

    def _stream(self, record: Record, items: Stream, asked_at: float) -> Any:
        """Sends each Partial on as it comes; the result that ends the stream."""
        result = None
        first = True
        try:
            for item in items:
                if not isinstance(item, Partial):
                    result = item
                    continue
                if first:
                    get_current_span().add_event("first piece", {"fields": list(item.fields)})
                    first = False
                with self._speaking.lock:  # a barge-in now drops this piece, or is after it
                    if not self._speaking.current(asked_at):
                        raise Skip("interrupted by a new utterance (barge-in)")
                    self.send({**record, **item.fields}, item.fields.keys())
        finally:  # a stream left early is closed now, ending the call's stream too
            items.close()
        if result is None:
            raise RuntimeError(f"{self.config.call.method} stream ended without a result")
        if not self._speaking.current(asked_at):  # its last piece was cut off
            raise Skip("interrupted by a new utterance (barge-in)")
        return result

    def send(self, record: Record, only: Collection[str] | None = None) -> None:
        """The record's fields to the outputs (`only`: to those that take these fields)."""
        for output in self.config.outputs:
            if only is not None and output.source not in only:
                continue
            value = record.get(output.source)
            if value is None:  # e.g. no annotated image this time
                continue
            if output.product is not None:
                self.products.put(output.product, value)
            else:
                self.emitter.emit(output, value, record)
        for watcher in self.watchers:
            watcher.show(self.name, record)

    def process(self, load: Loader) -> None:
        """Worker entry point: one message, every failure logged and counted, never raised.
        While tracing is on, the message's trace: receive, the call, post steps, publish."""
        context = load.trace_context if isinstance(load, TracedLoader) else None
        with span(f"route {self.name}", context=context,
                  attributes={"oricf.route": self.name}):
            self._process(load)

    def _process(self, load: Loader) -> None:
        started = time.perf_counter()
        asker = asker_of(load)
        try:
            with span("receive"):
                record = load()
            record = self.run(record)
            with span("publish"):
                self.send(record)
            self.latest = (time.monotonic(), record)
            asker.answered(record)
        except Skip as exc:
            get_current_span().set_attribute("oricf.skipped", str(exc))
            self.stats.skipped += 1
            log.info("route %s: nothing to send on: %s", self.name, exc)
            self._tell(asker, f"nothing to answer: {exc}")
            return
        except InvalidInput as exc:
            get_current_span().set_status(Status(StatusCode.ERROR, "bad input"))
            self.stats.bad_input += 1
            self.stats.count_error("bad_input")
            self._throttle.warning(f"{self.name}:bad_input:{exc}",
                                   "route %s: bad input dropped: %s", self.name, exc)
            self._tell(asker, f"bad input: {exc}")
            return
        except grpc.RpcError as exc:
            get_current_span().set_status(Status(StatusCode.ERROR, exc.code().name))
            self._call_failed(exc)
            details = f": {exc.details()}" if exc.code() in TOLD_IN_FULL else ""
            self._tell(asker, f"{self.config.call.method} failed: {exc.code().name}{details}")
            return
        except Exception:
            get_current_span().set_status(Status(StatusCode.ERROR, "internal"))
            self.stats.count_error("internal")
            log.exception("route %s: unexpected error (message dropped)", self.name)
            self._tell(asker, "internal error")
            return
        seconds = time.perf_counter() - started
        self.stats.ok += 1
        self.stats.last_ms = seconds * 1000
        self.stats.latency.observe(seconds)

    def close(self) -> None:
        """Lets go of what its method holds: after its worker stopped, before its endpoint
        closes."""
        self.method.close()

    def _call_failed(self, exc: grpc.RpcError) -> None:
        code = exc.code()
        self.stats.call_errors += 1
        self.stats.count_error(code.name)
        self._throttle.error(f"{self.name}:{code.name}",
                             "route %s: %s call to %s (%s) failed: %s %s", self.name,
                             self.config.call.method, self.endpoint.name,
                             self.endpoint.active.address, code.name,
                             quoted(exc.details() or "", 300))  # the server's words

    @staticmethod
    def _tell(asker: Asker, message: str) -> None:
        asker.fail(message[:500])
