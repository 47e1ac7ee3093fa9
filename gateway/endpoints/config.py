"""An endpoint's YAML: where its server is, how to talk to it, and what a call may take.

    endpoints:
      llm:
        address: 127.0.0.1:50053                 # ORICF's own service over gRPC
        deadline_ms: 20000
      vlm:
        protocol: openai                         # any OpenAI-compatible server
        address: http://edge.local:11434/v1      # e.g. Ollama; vLLM, llama.cpp's server
        model: gemma3:4b
        token: {env: EDGE_TOKEN}
        fallback: {address: 127.0.0.1:50053}     # another protocol: a target of its own
"""

from __future__ import annotations

from typing import Literal
from urllib.parse import urlsplit

from pydantic import Field, ValidationInfo, field_validator, model_validator

from oricf.config import Schema
from oricf.gateway.endpoints.placement import PlacementConfig
from oricf.gateway.endpoints.replicas import check_target, several_addresses
from oricf.tls import ClientTls, TokenSource

Protocol = Literal["grpc", "openai"]

# Metadata keys with a meaning of their own to HTTP/2 (hop-by-hop and framing headers), to
# gRPC (its transport sets them) or to tracing (W3C Trace Context, Baggage, B3): a token
# there would be dropped, refused by the transport or read as something else.
RESERVED_HEADERS = frozenset({
    "connection", "keep-alive", "proxy-connection", "transfer-encoding", "upgrade", "te",
    "trailer", "host", "content-type", "content-length", "content-encoding",
    "accept-encoding", "user-agent", "proxy-authorization", "proxy-authenticate",
    "traceparent", "tracestate", "baggage", "b3"})


class ImageTransport(Schema):
    transport: Literal["raw", "jpeg", "shm", "auto"] = Field(
        "raw", description="raw pixels (onboard: no encode cost), jpeg (remote: less "
                           "bandwidth), shm (raw pixels through system shared memory, for a "
                           "service on this host; the wire when that is not possible) or "
                           "auto (shm to a loopback address that offers it, else raw)")
    jpeg_quality: int = Field(80, ge=1, le=100)


class RetryConfig(Schema):
    """Retries of a call the server refused as busy (gRPC RESOURCE_EXHAUSTED, HTTP 429) or
    unavailable for a while it named (HTTP 503 with Retry-After), within its deadline: wait
    what the server asked for, or exponential backoff with jitter if longer."""

    attempts: int = Field(2, ge=0, le=10, description="retries after the first refusal")
    initial_backoff_ms: int = Field(50, ge=1, le=60_000)
    max_backoff_ms: int = Field(1000, ge=1, le=600_000)


def check_url(value: str) -> str:
    """An OpenAI-compatible API's base URL: http(s)://host[:port]/path, no credentials."""
    parts = urlsplit(value)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"'{value}' is not an http:// or https:// URL (e.g. "
                         f"http://127.0.0.1:11434/v1)")
    if parts.username or parts.password:
        raise ValueError(f"'{parts.hostname}': no user or password in the URL; give `token`")
    if parts.query or parts.fragment:
        raise ValueError(f"'{value}': a base URL has no query or fragment")
    return value.rstrip("/")


class TargetConfig(Schema):
    """One server: the protocol it speaks, its address, and how to reach it safely."""

    protocol: Protocol = Field("grpc", description="grpc (ORICF's services, Open Inference "
                                                   "Protocol servers) or openai")
    address: str = Field(description="grpc: host:port, or replicas to balance over "
                                     "(dns:///NAME:PORT, ipv4:IP:PORT,IP:PORT,...); openai: "
                                     "the API's base URL, http(s)://host:port/v1")
    model: str | None = Field(None, description="openai: the model's name on the server")
    tls: ClientTls | None = Field(None, description="TLS to the server (mTLS with cert/key)")
    token: TokenSource | None = Field(None, description="bearer token sent with every call")
    token_header: str | None = Field(
        None, pattern=r"^[a-z0-9][a-z0-9_.-]{0,127}$",
        description="grpc: the metadata key the token goes in, as the token itself (e.g. "
                    "triton-grpc-protocol-triton-access-token for Triton's restricted "
                    "protocols); default: authorization, as `Bearer TOKEN`")

    @field_validator("address")
    @classmethod
    def _address(cls, value: str, info: ValidationInfo) -> str:
        return check_address_for(info.data.get("protocol", "grpc"), value)

    @model_validator(mode="after")
    def _settings_for_protocol(self) -> TargetConfig:
        if self.protocol == "openai":
            if not self.model:
                raise ValueError("model: required with protocol openai (the name the server "
                                 "lists at GET /v1/models)")
            if self.address.startswith("http://") and self.tls is not None:
                raise ValueError("tls: given, but the address is http://; use https://")
            if self.tls is not None and self.tls.server_name is not None:
                raise ValueError("tls.server_name: only with protocol grpc; an https URL "
                                 "names the host its certificate must have")
        elif self.model is not None:
            raise ValueError("model: only with protocol openai (a gRPC service serves one)")
        if self.token_header is not None:
            if self.protocol != "grpc":
                raise ValueError("token_header: only with protocol grpc (an OpenAI-compatible "
                                 "server takes `Authorization: Bearer`)")
            if self.token is None:
                raise ValueError("token_header: given without a token")
            check_token_header(self.token_header)
        _check_server_name(self.protocol, self.address, self.tls)
        return self


def check_token_header(key: str) -> None:
    """ValueError unless `key` is a metadata key of its own for the token: not `authorization`
    (the default, where it goes as `Bearer TOKEN`), nor a key gRPC, HTTP/2 or tracing keep.
    The schema's pattern has already refused uppercase, spaces and pseudo-headers (`:path`)."""
    if key == "authorization":
        raise ValueError("token_header: authorization is where the token goes without "
                         "token_header, as `Bearer TOKEN`; leave token_header out")
    if key.startswith(("grpc-", "x-b3-")) or key.endswith("-bin") or key in RESERVED_HEADERS:
        raise ValueError(f"token_header: {key}: reserved (gRPC keeps grpc-* keys and *-bin "
                         f"ones carry bytes; HTTP/2 and tracing give this key a meaning of its "
                         f"own); name the key the server reads the token from")


def _check_server_name(protocol: str, address: str, tls: ClientTls | None) -> None:
    """TLS to replicas listed by address cannot take the certificate's name from a host."""
    if (protocol == "grpc" and tls is not None and tls.server_name is None
            and several_addresses(address)):
        raise ValueError(f"tls.server_name is needed with several addresses in one target "
                         f"({address}): the name the replicas' certificate has")


def check_address_for(protocol: str, value: str) -> str:
    if protocol == "openai":
        return check_url(value)
    if value.startswith(("http://", "https://")):
        raise ValueError(f"'{value}' is a URL: say `protocol: openai` (and `model`) for an "
                         f"OpenAI-compatible server; a gRPC address is host:port")
    return check_target(value)


class EndpointConfig(TargetConfig):
    """The primary target, inline, and what the calls to it may take."""

    fallback: str | TargetConfig | None = Field(
        None, description="used while the primary is unavailable: an address (same protocol, "
                          "model, TLS and token), or a target of its own")
    deadline_ms: int = Field(1000, gt=0, le=600_000, description="per call")
    probe_interval_s: float = Field(
        1.0, gt=0, le=60, description="readiness probe of the primary while on the fallback")
    image: ImageTransport = ImageTransport()
    retry: RetryConfig = RetryConfig()
    placement: PlacementConfig | None = Field(
        None, description="move calls between the address and the fallback by the preferred "
                          "one's latency against a budget, and the robot's CPU and battery, "
                          "not only when one fails (gateway/endpoints/placement.py)")

    @field_validator("fallback", mode="before")
    @classmethod
    def _fallback_address(cls, value: object, info: ValidationInfo) -> object:
        if isinstance(value, str):
            return check_address_for(info.data.get("protocol", "grpc"), value)
        return value

    @model_validator(mode="after")
    def _placement_needs_fallback(self) -> EndpointConfig:
        if self.placement is not None and self.fallback is None:
            raise ValueError("placement: needs a fallback to move calls to")
        return self

    @model_validator(mode="after")
    def _fallback_tls_name(self) -> EndpointConfig:
        if isinstance(self.fallback, str):  # the primary's TLS, at the fallback's address
            _check_server_name(self.protocol, self.fallback, self.tls)
        return self

    @property
    def targets(self) -> dict[str, TargetConfig]:
        """{"address": the primary, "fallback": the fallback (if any)}."""
        primary = TargetConfig(protocol=self.protocol, address=self.address, model=self.model,
                               tls=self.tls, token=self.token, token_header=self.token_header)
        found = {"address": primary}
        if isinstance(self.fallback, str):
            found["fallback"] = primary.model_copy(update={"address": self.fallback})
        elif self.fallback is not None:
            found["fallback"] = self.fallback
        return found
