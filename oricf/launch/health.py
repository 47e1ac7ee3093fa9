"""grpc.health.v1 checks, and the probe that containers run.

    python -m oricf.launch.health [ADDRESS] [--service NAME] [--timeout S]
        [--tls-ca CA.pem [--tls-cert CERT --tls-key KEY] [--server-name NAME]]

exits 0 when ADDRESS (default $ORICF_HEALTH_ADDRESS, else 127.0.0.1:50051) answers SERVING,
1 otherwise: the HEALTHCHECK of compose/Dockerfile and the compose files. Health checks need
no token (services exempt them), but a TLS service needs --tls-ca (and a client certificate
where it requires one).
"""

from __future__ import annotations

import argparse
import os
import random
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from oricf.tls import ClientTls, open_channel

SERVING = health_pb2.HealthCheckResponse.SERVING
DEFAULT_ADDRESS = "127.0.0.1:50051"
FREE_PORTS_FROM = 20000  # free_port's lowest: above the ports services are usually given


def status(address: str, service: str = "", timeout: float = 2.0,
           tls: ClientTls | None = None) -> str:
    """The health status name (SERVING, NOT_SERVING, ...), or UNREACHABLE."""
    with open_channel(address, tls) as channel:
        stub = health_pb2_grpc.HealthStub(channel)
        try:
            reply = stub.Check(health_pb2.HealthCheckRequest(service=service), timeout=timeout)
        except grpc.RpcError:
            return "UNREACHABLE"
    return str(health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status))


def wait_serving(address: str, timeout: float = 300.0,
                 process: subprocess.Popen[Any] | None = None,
                 tls: ClientTls | None = None) -> None:
    """Blocks until address answers SERVING; fails early if `process` (the server) exits."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            raise RuntimeError(f"the service exited with {process.returncode} before SERVING")
        if status(address, timeout=1.0, tls=tls) == "SERVING":
            return
        time.sleep(0.1)
    raise TimeoutError(f"{address} was not SERVING after {timeout} s")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing uses right now, for a process about to listen on
    it. Taken below the kernel's ephemeral range where there is room: a port from that range
    (what binding to port 0 gives) can be taken as the source port of any outgoing
    connection on the machine before the process binds it, which then fails to start."""
    low = ephemeral_ports()[0]
    for _ in range(100):
        port = random.randrange(FREE_PORTS_FROM, low) if low > FREE_PORTS_FROM else 0
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return int(sock.getsockname()[1])
    raise OSError(f"no free TCP port on 127.0.0.1 between {FREE_PORTS_FROM} and {low}")


def ephemeral_ports() -> tuple[int, int]:
    """The range the kernel takes outgoing connections' source ports from (Linux; else
    IANA's)."""
    try:
        low, high = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
        return int(low), int(high)
    except (OSError, ValueError):
        return 49152, 65535


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oricf.launch.health",
                                     description="exit 0 when a gRPC service is SERVING")
    parser.add_argument("address", nargs="?",
                        default=os.environ.get("ORICF_HEALTH_ADDRESS") or DEFAULT_ADDRESS)
    parser.add_argument("--service", default="", help="service name (default: the server)")
    parser.add_argument("--timeout", type=float, default=3.0, help="seconds for the call")
    parser.add_argument("--tls-ca", help="TLS: the CA that signed the service's certificate")
    parser.add_argument("--tls-cert", help="mTLS: this client's certificate")
    parser.add_argument("--tls-key", help="mTLS: its key")
    parser.add_argument("--server-name", help="TLS: the name in the service's certificate")
    args = parser.parse_args(argv)
    tls = None
    if args.tls_ca:
        tls = ClientTls(ca=args.tls_ca, cert=args.tls_cert, key=args.tls_key,
                        server_name=args.server_name)
    state = status(args.address, args.service, args.timeout, tls)
    print(f"{args.address}: {state}")
    return 0 if state == "SERVING" else 1


if __name__ == "__main__":
    sys.exit(main())
