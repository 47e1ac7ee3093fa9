"""llama.cpp's own OpenAI-compatible server (`python -m llama_cpp.server`, from
llama-cpp-python[server]) serving a shipped GGUF: a third-party engine on localhost, which
can be killed and started again on the same port."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import httpx

from oricf.store import ModelStore
from tests.support.processes import free_port

START_TIMEOUT_S = 60


class LlamaServer:
    def __init__(self, model: str = "smollm2-135m-instruct", alias: str = "smollm2") -> None:
        self.model_file = ModelStore().path(model)
        self.alias = alias
        self.port = free_port()
        self.process: subprocess.Popen[str] | None = None

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    def start(self) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "llama_cpp.server", "--model", str(self.model_file),
             "--model_alias", self.alias, "--host", "127.0.0.1", "--port", str(self.port),
             "--n_ctx", "2048", "--n_threads", "1", "--verbose", "false"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            start_new_session=True, env={**os.environ, "OMP_WAIT_POLICY": "PASSIVE"})
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                output = self.process.stdout.read() if self.process.stdout else ""
                raise RuntimeError(f"llama_cpp.server exited {self.process.returncode}: "
                                   f"{output[-2000:]}")
            try:
                if httpx.get(f"{self.base_url}/models", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        self.kill()
        raise RuntimeError(f"llama_cpp.server not ready on {self.port} in {START_TIMEOUT_S} s")

    def kill(self) -> None:
        if self.process is None:
            return
        if self.process.poll() is None:
            os.killpg(self.process.pid, 9)
        self.process.wait(timeout=10)
        if self.process.stdout:
            self.process.stdout.close()
        self.process = None


@contextmanager
def llama_server(**options: str) -> Iterator[LlamaServer]:
    server = LlamaServer(**options)
    server.start()
    try:
        yield server
    finally:
        server.kill()
