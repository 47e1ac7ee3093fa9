"""grpc.health.v1 checks, and the probe that containers run.

    python -m oricf.launch.health [ADDRESS] [--service NAME] [--timeout S]

exits 0 when ADDRESS (default $ORICF_HEALTH_ADDRESS, else 127.0.0.1:50051) answers SERVING,
1 otherwise: the HEALTHCHECK of compose/Dockerfile and the compose files.
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time
from typing import Any

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

SERVING = health_pb2.HealthCheckResponse.SERVING
DEFAULT_ADDRESS = "127.0.0.1:50051"


def status(address: str, service: str = "", timeout: float = 2.0) -> str:
    """The health status name (SERVING, NOT_SERVING, ...), or UNREACHABLE."""
    with grpc.insecure_channel(address) as channel:
        stub = health_pb2_grpc.HealthStub(channel)
        try:
            reply = stub.Check(health_pb2.HealthCheckRequest(service=service), timeout=timeout)
        except grpc.RpcError:
            return "UNREACHABLE"
    return str(health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status))


def wait_serving(address: str, timeout: float = 300.0,
                 process: subprocess.Popen[Any] | None = None) -> None:
    """Blocks until address answers SERVING; fails early if `process` (the server) exits."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            raise RuntimeError(f"the service exited with {process.returncode} before SERVING")
        if status(address, timeout=1.0) == "SERVING":
            return
        time.sleep(0.1)
    raise TimeoutError(f"{address} was not SERVING after {timeout} s")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oricf.launch.health",
                                     description="exit 0 when a gRPC service is SERVING")
    parser.add_argument("address", nargs="?",
                        default=os.environ.get("ORICF_HEALTH_ADDRESS") or DEFAULT_ADDRESS)
    parser.add_argument("--service", default="", help="service name (default: the server)")
    parser.add_argument("--timeout", type=float, default=3.0, help="seconds for the call")
    args = parser.parse_args(argv)
    state = status(args.address, args.service, args.timeout)
    print(f"{args.address}: {state}")
    return 0 if state == "SERVING" else 1


if __name__ == "__main__":
    sys.exit(main())
