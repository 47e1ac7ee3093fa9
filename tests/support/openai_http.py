"""A real `oricf serve NAME --http-listen` process and the official OpenAI client for it."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import openai
import yaml

from tests.support.processes import free_port, oricf_process, wait_serving

__all__ = ["HttpService", "client", "health", "http_service", "overlay", "rss_mb"]

LOAD_TIMEOUT_S = 120


@dataclass
class HttpService:
    process: subprocess.Popen[str]
    grpc_address: str
    base_url: str          # http://127.0.0.1:PORT, without /v1

    @property
    def port(self) -> int:
        return int(self.base_url.rpartition(":")[2])


@contextmanager
def http_service(name: str, *args: str, scheme: str = "http",
                 grpc_ready: Any = None) -> Iterator[HttpService]:
    """`oricf serve NAME` with gRPC and HTTP on free local ports, once its model is loaded.

    grpc_ready: a callable(address, process) that waits for the gRPC side (a TLS service
    needs its own probe); by default the plaintext health check."""
    grpc_address = f"127.0.0.1:{free_port()}"
    http_port = free_port()
    with oricf_process("serve", name, "--listen", grpc_address,
                       "--http-listen", f"127.0.0.1:{http_port}", *args) as process:
        if grpc_ready is None:
            wait_serving(grpc_address, timeout=LOAD_TIMEOUT_S, process=process)
        else:
            grpc_ready(grpc_address, process)
        yield HttpService(process, grpc_address, f"{scheme}://127.0.0.1:{http_port}")


def client(service: HttpService, api_key: str = "unused", **options: Any) -> openai.OpenAI:
    """The OpenAI client, retries off unless asked (a refusal must reach the test as it was
    sent)."""
    options = {"max_retries": 0, "timeout": 60, **options}
    return openai.OpenAI(base_url=f"{service.base_url}/v1", api_key=api_key, **options)


def overlay(folder: Path, data: dict[str, Any], name: str = "overlay.yaml") -> str:
    """A YAML overlay file for `oricf serve --overlay`."""
    path = folder / name
    path.write_text(yaml.safe_dump(data))
    return str(path)


def rss_mb(pid: int) -> float:
    """Resident memory of a process, MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for {pid}")


def health(service: HttpService, **options: Any) -> httpx.Response:
    return httpx.get(f"{service.base_url}/health", timeout=10, **options)
