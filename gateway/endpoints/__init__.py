"""Endpoints: the servers routes call, over gRPC (ORICF's services, Open Inference Protocol
servers) or the OpenAI-compatible HTTP API (Ollama, vLLM, llama.cpp's server, ...), with a
deadline on every call, retries while a server says it is busy, and failover.

State machine (per endpoint):

    PRIMARY --call fails UNAVAILABLE / DEADLINE_EXCEEDED--> FALLBACK (the call is retried there)
    FALLBACK --readiness probe of the primary says ready--> PRIMARY

A call the server refuses as busy (gRPC RESOURCE_EXHAUSTED, HTTP 429), or as unavailable
for a time it names (HTTP 503 with Retry-After), is retried on the same target after that
wait or an exponential backoff with jitter, whichever is longer, while its deadline allows
(`retry:` in the endpoint's YAML). The primary and the fallback may speak different
protocols (an Ollama on the edge, ORICF's language service onboard): a method says what a
call is in each protocol it speaks.

While on the fallback a background thread probes the primary every probe_interval_s:
grpc.health.v1 (or the Open Inference Protocol's ServerReady), or GET /models. Without a
fallback, errors go back to the caller (the route logs them).

A gRPC address may name several replicas (dns:///NAME:PORT, ipv4:A:P,B:P): gRPC then
balances calls over the healthy ones and retries a call on another replica when one dies
under it (replicas.py); the endpoint fails over only once none is left.
"""

from oricf.gateway.endpoints.config import (
    EndpointConfig,
    ImageTransport,
    RetryConfig,
    TargetConfig,
)
from oricf.gateway.endpoints.endpoint import Endpoint
from oricf.gateway.endpoints.grpc import CHANNEL_OPTIONS, GrpcTarget, Metadata, Ready, Service

__all__ = ["CHANNEL_OPTIONS", "Endpoint", "EndpointConfig", "GrpcTarget", "ImageTransport",
           "Metadata", "Ready", "RetryConfig", "Service", "TargetConfig"]
