"""Real `oricf` processes for tests: free ports, readiness, no orphans."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def health_status(address: str, service: str = "", timeout: float = 2.0) -> int | None:
    """The grpc.health.v1 status, or None when nothing answers."""
    with grpc.insecure_channel(address) as channel:
        stub = health_pb2_grpc.HealthStub(channel)
        try:
            request = health_pb2.HealthCheckRequest(service=service)
            return int(stub.Check(request, timeout=timeout).status)
        except grpc.RpcError:
            return None


def wait_serving(address: str, timeout: float = 120.0,
                 process: subprocess.Popen[str] | None = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            raise RuntimeError(f"process exited with {process.returncode} before SERVING")
        if health_status(address) == health_pb2.HealthCheckResponse.SERVING:
            return
        time.sleep(0.1)
    raise TimeoutError(f"{address} not SERVING after {timeout} s")


@contextmanager
def oricf_process(*args: str, env: dict[str, str] | None = None
                  ) -> Iterator[subprocess.Popen[str]]:
    """`python -m oricf ARGS` in its own process group, killed on exit whatever happens."""
    process = subprocess.Popen(
        [sys.executable, "-m", "oricf", *args], env={**os.environ, **(env or {})},
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        yield process
    finally:
        if process.poll() is None:
            os.killpg(process.pid, 9)
        process.wait(timeout=10)
        if process.stdout:
            process.stdout.close()
