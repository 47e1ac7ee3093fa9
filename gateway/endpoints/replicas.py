"""Endpoints served by several replicas: gRPC's own round robin over a target's addresses.

    address: 127.0.0.1:50051                          one server
    address: dns:///detector.oricf.svc.cluster.local:50051
                                                      every address the name resolves to
                                                      (a headless Kubernetes Service)
    address: ipv4:10.0.0.5:50051,10.0.0.6:50051       these replicas (ipv6:[::1]:50051,...)

A target that names replicas gets a channel that spreads calls over them round robin, watches
each one's grpc.health.v1 status (client-side health checking: a replica still loading its
model, or draining after SIGTERM, gets no calls; a server without grpc.health.v1 counts as
healthy), and retries a call that failed UNAVAILABLE, which is what a replica dying under a
call gives, on another replica within the call's deadline. Every ORICF RPC is a pure function
of its request, so running one twice is harmless. A plain host:port keeps gRPC's default
(the first address that connects), as before.
"""

from __future__ import annotations

import ipaddress
import json

from oricf.hosts import Address

SCHEMES = ("dns:", "ipv4:", "ipv6:")
# The ORICF services take up to 16 MB per message; gRPC keeps a request for a retry only
# while it fits this buffer (256 KiB by default, less than one raw 640x480 frame).
RETRY_BUFFER_BYTES = 64 * 1024 * 1024
SERVICE_CONFIG = json.dumps({
    "loadBalancingConfig": [{"round_robin": {}}],
    "healthCheckConfig": {"serviceName": ""},
    "methodConfig": [{
        "name": [{}],  # every method
        "retryPolicy": {"maxAttempts": 3, "initialBackoff": "0.02s", "maxBackoff": "0.2s",
                        "backoffMultiplier": 2, "retryableStatusCodes": ["UNAVAILABLE"]},
    }],
})
FORMS = ("host:port, dns:///host:port, ipv4:IP:PORT,IP:PORT,... or "
         "ipv6:[IP]:PORT,[IP]:PORT,...")


def _literal(address: str, version: int) -> str:
    host = Address.parse(address).host
    bracketed = address.startswith("[")  # gRPC reads an IPv6 literal only in brackets
    if version == 6 and not bracketed:
        raise ValueError(f"'{address}': an ipv6: address is [IP]:PORT")
    try:
        if ipaddress.ip_address(host).version == version and bracketed == (version == 6):
            return address
    except ValueError:
        pass
    raise ValueError(f"'{address}' is not an IPv{version} address and port (for names: "
                     f"dns:///NAME:PORT)")


def check_target(value: str) -> str:
    """A host:port, or a gRPC target naming replicas (FORMS); ValueError otherwise."""
    scheme, _, rest = value.partition(":")
    if not value.startswith(SCHEMES):
        if "://" in value:
            raise ValueError(f"'{value}': the scheme '{scheme}' is not one of {FORMS}")
        Address.parse(value)
        return value
    if scheme == "dns":
        # dns:host:port, dns:///host:port, or dns://DNS-SERVER/host:port
        name = rest.split("/", 3)[3] if rest.startswith("//") and rest.count("/") >= 3 else rest
        Address.parse(name)
        return value
    addresses = rest.split(",")
    for address in addresses:
        _literal(address, 4 if scheme == "ipv4" else 6)
    return value


def spreads(target: str) -> bool:
    """Whether the target names replicas to balance over."""
    return target.startswith(SCHEMES)


def several_addresses(target: str) -> bool:
    """An ipv4:/ipv6: list of more than one: TLS cannot take a host name from it."""
    return target.startswith(("ipv4:", "ipv6:")) and "," in target


def channel_options(target: str, options: list[tuple[str, object]]
                    ) -> list[tuple[str, object]]:
    """options, plus round robin, health checking and retries for a target of replicas."""
    if not spreads(target):
        return options
    return [*options, ("grpc.service_config", SERVICE_CONFIG),
            ("grpc.per_rpc_retry_buffer_size", RETRY_BUFFER_BYTES)]
