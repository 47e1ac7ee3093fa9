"""OpenTelemetry traces of a process (docs/tracing.md): off unless asked for.

On when the standard OTEL_EXPORTER_OTLP_ENDPOINT or OTEL_EXPORTER_OTLP_TRACES_ENDPOINT is
set, or when the process' YAML says `tracing: {enabled: true}` (a service's `server:`, the
gateway's pipeline). Spans go over OTLP, gRPC or HTTP/protobuf as
OTEL_EXPORTER_OTLP_TRACES_PROTOCOL (or OTEL_EXPORTER_OTLP_PROTOCOL) says; the exporters read
the other standard variables (headers, certificates, timeouts) themselves. OTEL_SDK_DISABLED
turns it off whatever else is set.

The SDK and the exporters are the `tracing` extra: opentelemetry-api alone (installed with
ORICF's dependencies) gives the API's no-op tracer, which is what every span site uses while
tracing is off. The W3C trace context (`traceparent`) travels in gRPC metadata, through the
propagators that OTEL_PROPAGATORS names (tracecontext and baggage unless it says otherwise).

At exit, the spans not yet exported get SHUTDOWN_S: a backend that refuses or never answers
delays a stop by no more than that (the SDK alone would wait up to 30 s).
"""

from __future__ import annotations

import atexit
import logging
import os
import threading
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext
from typing import TYPE_CHECKING, Any

from opentelemetry import context as otel_context
from opentelemetry import propagate, trace
from pydantic import Field

from oricf.config import Schema
from oricf.errors import ConfigError

if TYPE_CHECKING:  # the SDK is the optional `tracing` extra
    from opentelemetry.sdk.trace import TracerProvider

log = logging.getLogger(__name__)

ENDPOINT_VARIABLES = ("OTEL_EXPORTER_OTLP_TRACES_ENDPOINT", "OTEL_EXPORTER_OTLP_ENDPOINT")
PROTOCOL_VARIABLES = ("OTEL_EXPORTER_OTLP_TRACES_PROTOCOL", "OTEL_EXPORTER_OTLP_PROTOCOL")
# The OpenTelemetry specification's default protocol for OTLP exporters.
DEFAULT_PROTOCOL = "http/protobuf"
SCOPE = "oricf"
INSTALL_HINT = "pip install 'oricf[tracing]' (scripts/setup.sh --dev installs it)"

# The longest a stopping process waits for its last spans to be exported.
SHUTDOWN_S = 2.0

_NO_OP = trace.NoOpTracer()
# The tracer every span site asks for: the no-op one until traces are turned on.
_tracer: trace.Tracer = _NO_OP


class TracingConfig(Schema):
    """`tracing:` in a service's `server:` or in a pipeline."""

    enabled: bool = Field(
        False, description="export traces over OTLP even without OTEL_EXPORTER_OTLP_ENDPOINT "
                           "(the exporters' default: localhost:4318, or :4317 over gRPC)")


def tracer() -> trace.Tracer:
    """The process' tracer (no-op while tracing is off)."""
    return _tracer


def active() -> bool:
    """Whether spans are recorded and exported (sites that do extra work check first)."""
    return _tracer is not _NO_OP


_OFF = nullcontext()


def span(name: str, context: otel_context.Context | None = None,
         attributes: dict[str, Any] | None = None) -> AbstractContextManager[Any]:
    """A span current for a block, a child of the current one (or of `context`). While
    tracing is off, a shared empty block: a frame's spans cost a global's read each, where
    the API's no-op tracer would still make and attach a context per span (about 10 us)."""
    if _tracer is _NO_OP:
        return _OFF
    return _tracer.start_as_current_span(name, context=context, attributes=attributes)


def wanted(config: TracingConfig | None, environ: dict[str, str] | None = None) -> bool:
    env = os.environ if environ is None else environ
    if env.get("OTEL_SDK_DISABLED", "").strip().lower() == "true":
        return False
    return any(env.get(name) for name in ENDPOINT_VARIABLES) or bool(config and config.enabled)


def protocol(environ: dict[str, str] | None = None) -> str:
    env = os.environ if environ is None else environ
    for name in PROTOCOL_VARIABLES:
        if env.get(name):
            value = env[name].strip().lower()
            if value not in ("grpc", "http/protobuf"):
                raise ConfigError(f"{name}={env[name]}: ORICF exports traces over 'grpc' or "
                                  f"'http/protobuf'")
            return value
    return DEFAULT_PROTOCOL


def setup_tracing(service_name: str, config: TracingConfig | None = None) -> bool:
    """Turns traces on for this process when asked for (once; later calls do nothing).
    `service_name` is the resource's service.name unless OTEL_SERVICE_NAME names one.
    Returns whether traces are on."""
    if active():
        return True
    if not wanted(config):
        return False
    chosen = protocol()
    try:
        provider = _provider(service_name, chosen)
    except ImportError as exc:
        raise ConfigError(f"tracing is on (OTEL_EXPORTER_OTLP_ENDPOINT or tracing.enabled) but "
                          f"the OpenTelemetry SDK is missing ({exc.name}): {INSTALL_HINT}"
                          ) from None
    trace.set_tracer_provider(provider)  # for libraries that trace through the global one
    use_provider(provider)
    endpoint = next((os.environ[n] for n in ENDPOINT_VARIABLES if os.environ.get(n)),
                    "the exporter's default endpoint")
    log.info("traces of %s go over OTLP (%s) to %s", service_name, chosen, endpoint)
    return True


def _provider(service_name: str, chosen: str) -> TracerProvider:
    from opentelemetry.sdk.resources import SERVICE_NAME, Resource
    from opentelemetry.sdk.trace import TracerProvider
    from opentelemetry.sdk.trace.export import BatchSpanProcessor

    if chosen == "grpc":
        from opentelemetry.exporter.otlp.proto.grpc.trace_exporter import OTLPSpanExporter
    else:
        from opentelemetry.exporter.otlp.proto.http.trace_exporter import (  # type: ignore[assignment]
            OTLPSpanExporter,
        )
    attributes = {} if os.environ.get("OTEL_SERVICE_NAME") else {SERVICE_NAME: service_name}
    # The SDK's own exit handler would wait up to 30 s for a backend that does not answer.
    provider = TracerProvider(resource=Resource.create(attributes), shutdown_on_exit=False)
    provider.add_span_processor(BatchSpanProcessor(OTLPSpanExporter()))
    atexit.register(shutdown_within, provider, SHUTDOWN_S)
    return provider


def shutdown_within(provider: TracerProvider, timeout_s: float) -> bool:
    """Shuts the provider down (its last spans exported), waiting for that at most
    timeout_s: a process that stops never waits longer on its traces' backend (the spans
    left are dropped). Runs at exit, after the process' own stop (a control loop's safe
    action, an agent's zero command) is done. Returns whether it finished in time."""
    done = threading.Thread(target=provider.shutdown, name="oricf-tracing-shutdown",
                            daemon=True)
    done.start()
    done.join(timeout_s)
    if done.is_alive():
        log.warning("traces not exported within %g s of stopping (the OTLP endpoint does "
                    "not answer): the rest are dropped", timeout_s)
        return False
    return True


def use_provider(provider: Any | None) -> None:
    """Spans from now on go to this provider's tracer (None: back to the no-op one). For
    setup_tracing, and for tests and embedders with a provider of their own."""
    global _tracer
    _tracer = _NO_OP if provider is None else provider.get_tracer(SCOPE)


@contextmanager
def traced_with(provider: Any) -> Iterator[None]:
    """use_provider for a block, then tracing as it was."""
    global _tracer
    before = _tracer
    use_provider(provider)
    try:
        yield
    finally:
        _tracer = before


def inject(metadata: Sequence[tuple[str, str]]) -> tuple[tuple[str, str], ...]:
    """gRPC call metadata plus the current span's trace context (`traceparent`)."""
    if not active():
        return tuple(metadata)
    carrier: dict[str, str] = {}
    propagate.inject(carrier)
    return (*metadata, *carrier.items())


def extract(metadata: Sequence[tuple[str, Any]] | None) -> otel_context.Context:
    """The trace context a caller sent in its gRPC metadata (an empty one if none)."""
    carrier = {key: value for key, value in metadata or () if isinstance(value, str)}
    return propagate.extract(carrier)

