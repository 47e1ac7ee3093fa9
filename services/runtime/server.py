"""The one lifecycle every ORICF model service shares.

Open the port with health NOT_SERVING, load the model, flip health to SERVING, serve with
a concurrency limit and a message size limit, and on SIGTERM/SIGINT: health NOT_SERVING,
drain in-flight calls within the grace period, close the model, exit 0.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from concurrent import futures
from typing import TYPE_CHECKING, Any

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection
from prometheus_client import CollectorRegistry

from oricf.errors import ConfigError
from oricf.metrics import MetricsServer
from oricf.services.runtime.auth import TokenAuthInterceptor
from oricf.services.runtime.config import ServiceConfig
from oricf.services.runtime.errors import ErrorMappingInterceptor
from oricf.services.runtime.limits import EXEMPT_STREAMS, CallLimit
from oricf.services.runtime.metrics import service_registry
from oricf.services.runtime.model import Model, ModelSlot
from oricf.services.runtime.parts import ServiceParts
from oricf.services.runtime.probe import probe_server
from oricf.signals import stop_on_signals
from oricf.tracing import active as tracing_active
from oricf.tracing import setup_tracing

if TYPE_CHECKING:  # Starlette and uvicorn load only for a service that serves HTTP
    from oricf.services.runtime.http.server import HttpServer

log = logging.getLogger(__name__)

# Threads beyond the call limit, so that a refused call is refused at once rather than
# waiting for a thread, and health checks are answered while the service is busy.
SPARE_WORKERS = 4
# How long past the grace period a stop may take before the process exits anyway: a call
# stuck in a servicer must not keep a stopping service alive forever.
STOP_MARGIN_S = 5.0


class ServiceHost:
    """A gRPC server around one model: build, start, load, stop."""

    def __init__(self, spec: ServiceParts, config: ServiceConfig, model: Model,
                 listen: str | None = None) -> None:
        self.spec = spec
        self.config = config
        self.slot: ModelSlot[Any] = ModelSlot(model)
        settings = config.server
        limit = settings.max_concurrent_rpcs
        call_limit = self.call_limit = CallLimit(limit, settings.retry_after_ms)
        interceptors: list[grpc.ServerInterceptor] = []
        self.metrics: CollectorRegistry | None = None
        self.metrics_server: MetricsServer | None = None
        if settings.metrics is not None:
            # First: the outermost interceptor sees every call's final status, refusals too.
            self.metrics, calls = service_registry(spec.name, self.slot, call_limit)
            interceptors.append(calls)
        if tracing_active():  # a span per call, refused ones too (docs/tracing.md)
            from oricf.services.runtime.tracing import TracingInterceptor

            interceptors.append(TracingInterceptor())
        if settings.auth is not None:
            interceptors.append(TokenAuthInterceptor(settings.auth.tokens()))
        streams = spec.message_streams(config) if spec.message_streams else None
        interceptors.append(ErrorMappingInterceptor(call_limit, streams,
                                                    settings.reflection_idle_s))
        # A thread for each stream that may be open (message streams, reflection's), beside
        # those for calls: quiet streams must leave threads for everyone else's calls.
        workers = (limit + SPARE_WORKERS + (limit if streams is not None else 0)
                   + (EXEMPT_STREAMS if settings.reflection else 0))
        self._workers = futures.ThreadPoolExecutor(max_workers=workers,
                                                   thread_name_prefix=f"{spec.name}-rpc")
        self.server = grpc.server(
            self._workers,
            interceptors=interceptors,
            options=[
                ("grpc.max_receive_message_length", settings.max_message_bytes),
                ("grpc.max_send_message_length", settings.max_message_bytes),
                ("grpc.so_reuseport", 0),
                *_connection_age(settings.max_connection_age_s, settings.grace_s),
            ],
        )
        spec.add_servicer(self.server, self.slot, config)
        self.health = health.HealthServicer(experimental_non_blocking=True)
        health_pb2_grpc.add_HealthServicer_to_server(self.health, self.server)
        self.probe: tuple[grpc.Server, int] | None = (
            probe_server(self.health, settings.health_listen) if settings.health_listen else None)
        if settings.reflection:
            reflection.enable_server_reflection(
                [spec.service_name, health.SERVICE_NAME, reflection.SERVICE_NAME], self.server)
        self.address = listen or settings.listen
        try:
            self.port = (self.server.add_secure_port(self.address, settings.tls.credentials())
                         if settings.tls else self.server.add_insecure_port(self.address))
        except RuntimeError as exc:
            raise ConfigError(f"cannot listen on {self.address}: {exc}") from None
        if self.port == 0:
            raise ConfigError(f"cannot listen on {self.address} (port in use?)")
        self._set_health(health_pb2.HealthCheckResponse.NOT_SERVING)
        self.draining = False
        self.http = self._http_server() if settings.http is not None else None

    def _http_server(self) -> HttpServer:
        """The OpenAI-compatible HTTP API on the same model and call limit (bound now)."""
        from oricf.services.runtime.http import http_server

        return http_server(self.spec, self.slot, self.config, self.call_limit, self.metrics,
                           lambda: self.draining)

    def _set_health(self, status: int) -> None:
        self.health.set("", status)
        self.health.set(self.spec.service_name, status)

    def start(self) -> None:
        settings = self.config.server
        if settings.metrics is not None and self.metrics is not None:
            # Before the model loads: a scrape shows it loading (oricf_model_ready 0).
            self.metrics_server = MetricsServer(settings.metrics, self.metrics)
        self.server.start()
        if self.probe is not None:
            self.probe[0].start()
            log.info("%s: health checks (Check only, plaintext) on port %d", self.spec.name,
                     self.probe[1])
        security = ("mTLS" if settings.tls and settings.tls.client_ca else
                    "TLS" if settings.tls else "plaintext")
        if settings.auth is not None:
            security += ", bearer tokens"
        log.info("%s listening on port %d (%s; health NOT_SERVING until the model loads)",
                 self.spec.name, self.port, security)
        if self.http is not None:
            self.http.start()
            log.info("%s: OpenAI-compatible HTTP API on port %d (%s; /health 503 until the "
                     "model loads)", self.spec.name, self.http.port, security)

    def load_model(self) -> None:
        seconds = self.slot.load()
        self._set_health(health_pb2.HealthCheckResponse.SERVING)
        providers = self.slot.peek().info().providers
        log.info("%s model loaded in %.1f s%s; SERVING", self.spec.name, seconds,
                 f", runs on {providers[0]}" if providers else "")

    def stop(self, grace: float | None = None) -> bool:
        """NOT_SERVING first (load balancers stop sending), then drain, then close the model.
        Returns False when calls were still stuck STOP_MARGIN_S after the grace period."""
        grace = self.config.server.grace_s if grace is None else grace
        self.health.enter_graceful_shutdown()
        self.draining = True
        self.slot.flush()
        log.info("%s draining (grace %.1f s)", self.spec.name, grace)
        deadline = time.monotonic() + grace + STOP_MARGIN_S
        grpc_done = self.server.stop(grace)
        http_stopped = self.http is None or self.http.stop(grace)
        stopped = grpc_done.wait(max(0.0, deadline - time.monotonic())) and http_stopped
        workers = threading.Thread(target=self._workers.shutdown, kwargs={"wait": True},
                                   daemon=True, name=f"{self.spec.name}-stop")
        workers.start()
        workers.join(max(0.0, deadline - time.monotonic()))
        self.slot.close()
        if self.probe is not None:  # answered NOT_SERVING while draining
            self.probe[0].stop(0)
        if self.metrics_server is not None:
            self.metrics_server.close()
        if stopped and not workers.is_alive():
            log.info("%s stopped", self.spec.name)
            return True
        log.warning("%s: calls still running %.1f s after the grace period; exiting anyway",
                    self.spec.name, STOP_MARGIN_S)
        return False


def _connection_age(age_s: float | None, grace_s: float) -> list[tuple[str, int]]:
    """server.max_connection_age_s as grpc options: GOAWAY after that long, then grace_s for
    the calls in flight."""
    if age_s is None:
        return []
    return [("grpc.max_connection_age_ms", int(age_s * 1000)),
            ("grpc.max_connection_age_grace_ms", int(grace_s * 1000))]


def serve(spec: ServiceParts, config: ServiceConfig, model: Model, listen: str | None) -> int:
    """Runs a service until SIGTERM/SIGINT; returns the process exit code."""
    setup_tracing(f"oricf-{spec.name}", config.server.tracing)
    with stop_on_signals() as stop:
        host = ServiceHost(spec, config, model, listen)
        host.start()
        try:
            host.load_model()
        except Exception:
            host.server.stop(0)
            if host.http is not None:
                host.http.stop(0)
            if host.probe is not None:
                host.probe[0].stop(0)
            raise
        while not stop.wait(0.5):
            pass
        if not host.stop():
            # Stuck call threads would block the interpreter's exit: leave without them.
            logging.shutdown()
            os._exit(1)
    return 0
