"""The part of every service's YAML that the shared runtime reads."""

from __future__ import annotations

from pydantic import Field, field_validator

from oricf.config import Schema
from oricf.hosts import listen_address
from oricf.metrics import MetricsConfig
from oricf.tls import ServerTls, TokenSource
from oricf.tracing import TracingConfig

# A raw 1920x1080 RGB frame is 6.2 MB; leave room for the rest of the message.
DEFAULT_MAX_MESSAGE_MB = 16
# A robot's computer shares a few gigabytes among all its services: enough for one image at
# the largest size a service accepts (imaging.MAX_PIXELS), or many camera frames at once.
DEFAULT_MAX_INFLIGHT_MB = 512


class HttpSettings(Schema):
    """The OpenAI-compatible HTTP API beside gRPC (docs/openai.md): the same model, call
    limit, TLS and tokens."""

    listen: str = Field(description="host:port (a bare port means 127.0.0.1:PORT; port 0 "
                                    "picks a free port)")
    max_body_kb: int = Field(1024, ge=1, le=1_048_576, description="largest JSON request body")
    max_upload_mb: float = Field(25.0, gt=0, le=1024,
                                 description="largest multipart upload (an audio file)")
    max_connections: int = Field(
        64, ge=1, le=10_000, description="open connections and requests; more get 503 at once")
    request_timeout_s: float = Field(
        30.0, gt=0, le=3600, description="a client must send its headers and whole body within "
                                         "this; slower ones are cut off (408 or closed)")
    keep_alive_s: float = Field(5.0, gt=0, le=600,
                                description="an idle connection is closed after this")

    @field_validator("listen", mode="before")
    @classmethod
    def _host_port(cls, value: object) -> object:
        if isinstance(value, (int, str)) and not isinstance(value, bool):
            return str(listen_address(value))  # loopback unless a host is named
        return value

    @property
    def max_body_bytes(self) -> int:
        return self.max_body_kb * 1024

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1024 * 1024)


class ServerSettings(Schema):
    listen: str = Field("0.0.0.0:50051", description="host:port; port 0 picks a free port")
    max_message_mb: float = Field(DEFAULT_MAX_MESSAGE_MB, gt=0, le=512)
    max_concurrent_rpcs: int = Field(
        8, ge=1, le=1024, description="calls beyond this get RESOURCE_EXHAUSTED at once")
    grace_s: float = Field(5.0, ge=0, le=600, description="drain time for in-flight calls")
    max_inflight_mb: float = Field(
        DEFAULT_MAX_INFLIGHT_MB, gt=0, le=65_536,
        description="decoded images and input tensors that calls may hold at once, estimated "
                    "before decoding; a call that does not fit gets RESOURCE_EXHAUSTED")
    tls: ServerTls | None = Field(None, description="serve TLS (mTLS with client_ca)")
    auth: TokenSource | None = Field(None, description="require one of these bearer tokens")
    reflection: bool = Field(True, description="serve gRPC reflection (grpcurl without protos)")
    reflection_idle_s: float = Field(
        10.0, gt=0, le=3600,
        description="a reflection stream that asks nothing this long is closed "
                    "(DEADLINE_EXCEEDED); a few are open at once, more get RESOURCE_EXHAUSTED")
    metrics: MetricsConfig | None = Field(
        None, description="serve Prometheus metrics at http://LISTEN/metrics (off if absent)")
    retry_after_ms: int = Field(
        100, ge=1, le=60_000,
        description="a refused call is told to wait 1-2x this long (grpc-retry-pushback-ms)")
    health_listen: str | None = Field(
        None, description="also answer grpc.health.v1 Check, and nothing else, in plaintext "
                          "on this host:port: for probes that cannot present a client "
                          "certificate (Kubernetes' gRPC probes)")
    max_connection_age_s: float | None = Field(
        None, gt=0, le=86_400,
        description="close each client connection this long after it opened (in-flight calls "
                    "get grace_s to finish), so clients resolving a name again find replicas "
                    "that were added since")

    http: HttpSettings | None = Field(
        None, description="also serve the OpenAI-compatible HTTP API (off if absent)")
    tracing: TracingConfig | None = Field(
        None, description="OpenTelemetry traces over OTLP (docs/tracing.md; also on when "
                          "OTEL_EXPORTER_OTLP_ENDPOINT is set)")

    @property
    def max_message_bytes(self) -> int:
        return int(self.max_message_mb * 1024 * 1024)

    @property
    def max_inflight_bytes(self) -> int:
        return int(self.max_inflight_mb * 1024 * 1024)


class ServiceConfig(Schema):
    """Base of each service's config schema: the server part plus the service's own keys."""

    server: ServerSettings = ServerSettings()
