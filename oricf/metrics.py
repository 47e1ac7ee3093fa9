"""Prometheus metrics over HTTP, shared by the model services and the gateway.

    metrics:
      listen: 127.0.0.1:9101        # the scrape address; off when the key is absent
      tls: {cert: server.pem, key: server.key, client_ca: ca.pem}   # optional

A process gets its own CollectorRegistry (two services or two pipelines in one test process
must not share counters) and serves it at http://HOST:PORT/metrics in Prometheus' text
format (OpenMetrics when the scraper asks for it). Counts live where the code already keeps
them and are read at scrape time by collectors, so nothing is counted twice.

Metrics carry no secrets (method names, counts, model names, addresses), but the shipped
configs still bind 127.0.0.1; a remote scraper gets TLS, with client certificates if
`client_ca` is set. The TLS handshake runs in the connection's own thread, so a client that
connects and never completes it cannot stall other scrapes (prometheus_client's own
start_http_server does the handshake on the accepting thread).
"""

from __future__ import annotations

import bisect
import logging
import socket
import ssl
import threading
from collections.abc import Sequence
from typing import Any, ClassVar
from wsgiref.simple_server import WSGIRequestHandler

from prometheus_client import (
    CollectorRegistry,
    PlatformCollector,
    disable_created_metrics,
    make_wsgi_app,
)
from prometheus_client.exposition import ThreadingWSGIServer
from prometheus_client.process_collector import ProcessCollector
from pydantic import Field

from oricf.errors import ConfigError
from oricf.hosts import Address, ListenAddress
from oricf.tls import Exposure, Listener, ServerTls

log = logging.getLogger(__name__)

# Seconds: from a detection (milliseconds) to a long language-model answer (a minute).
LATENCY_BUCKETS_S = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
                     60.0, 120.0)
# A connection that neither completes its TLS handshake nor sends its request in this time
# is closed (a scrape takes milliseconds).
CONNECTION_TIMEOUT_S = 10.0


def new_registry() -> CollectorRegistry:
    """A registry of one's own, with the process' CPU, memory and open files
    (process_*) and the Python version (python_info) that the default registry has."""
    # No `_created` series beside every counter and histogram: they double what a scrape
    # carries, and Prometheus drops them unless told to ingest creation times.
    disable_created_metrics()
    registry = CollectorRegistry()
    ProcessCollector(registry=registry)
    PlatformCollector(registry=registry)
    return registry


class MetricsConfig(Listener):
    """Open to any address (Exposure.OPEN): a scrape is counts, no secrets; compose and
    Kubernetes scrape the services across their networks."""

    listen: ListenAddress = Field(description="host:port of the /metrics endpoint (127.0.0.1: "
                                              "this machine only; port 0 picks a free port)")
    exposure: ClassVar[Exposure] = Exposure.OPEN


class _Handler(WSGIRequestHandler):
    timeout = CONNECTION_TIMEOUT_S

    def log_message(self, format: str, *args: Any) -> None:
        """Scrapes come every few seconds: not worth a log line each."""


class _Server(ThreadingWSGIServer):
    def __init__(self, address: tuple[str, int], context: ssl.SSLContext | None) -> None:
        self.address_family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
        self.ssl_context = context
        super().__init__(address, _Handler)

    def finish_request(self, request: Any, client_address: Any) -> None:
        if self.ssl_context is None:
            super().finish_request(request, client_address)
            return
        request.settimeout(CONNECTION_TIMEOUT_S)
        try:
            secure = self.ssl_context.wrap_socket(request, server_side=True)
        except (ssl.SSLError, OSError) as exc:  # no certificate, plain HTTP, a port scan
            log.debug("metrics: TLS handshake with %s failed: %s", client_address, exc)
            return
        with secure:
            super().finish_request(secure, client_address)


def _ssl_context(tls: ServerTls) -> ssl.SSLContext:
    return tls.ssl_context("metrics.tls")


class MetricsServer:
    """Serves a registry at /metrics until closed."""

    def __init__(self, config: MetricsConfig, registry: CollectorRegistry) -> None:
        context = _ssl_context(config.tls) if config.tls else None
        try:
            self._server = _Server((config.listen.host, config.listen.port), context)
        except OSError as exc:
            raise ConfigError(f"metrics: cannot listen on {config.listen}: "
                              f"{exc.strerror or exc}") from None
        self._server.set_app(make_wsgi_app(registry))
        self.port: int = self._server.server_address[1]
        bound = Address(config.listen.host, self.port)
        self.url = f"{'https' if context else 'http'}://{bound}/metrics"
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True,
                                        name="metrics-http")
        self._thread.start()
        log.info("metrics at %s", self.url)

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=5)


class LatencyHistogram:
    """Durations in cumulative buckets (Prometheus histogram semantics: a bucket counts the
    values <= its bound), kept by the code that measures them and read at scrape time."""

    def __init__(self, bounds: Sequence[float] = LATENCY_BUCKETS_S) -> None:
        self.bounds = tuple(bounds)
        self._counts = [0] * (len(self.bounds) + 1)  # the last: above every bound
        self._sum = 0.0
        self._lock = threading.Lock()

    def observe(self, seconds: float) -> None:
        index = bisect.bisect_left(self.bounds, seconds)
        with self._lock:
            self._counts[index] += 1
            self._sum += seconds

    def snapshot(self) -> tuple[list[tuple[str, float]], float]:
        """([(le, cumulative count), ..., ("+Inf", total)], sum of the values)."""
        with self._lock:
            counts, total = list(self._counts), self._sum
        buckets, running = [], 0
        for bound, count in zip((*map(str, self.bounds), "+Inf"), counts, strict=True):
            running += count
            buckets.append((bound, float(running)))
        return buckets, total
