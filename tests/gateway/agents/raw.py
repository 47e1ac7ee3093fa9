"""`oricf mcp` over stdio fed raw lines, as a careless or hostile client would write them, and
a pipeline that needs no model and no ROS: a text channel, a route to a speech synthesizer
that is not there (never called), and an agent target on a text channel that needs approval
by elicitation."""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import yaml

from tests.gateway.agents.session import server_env
from tests.support.processes import free_port

PROTOCOL = "2025-11-25"


def approval_pipeline(folder: Path, approval_timeout_s: float = 30.0) -> Path:
    config = {
        "endpoints": {"tts": {"address": f"127.0.0.1:{free_port()}", "deadline_ms": 500}},
        "channels": {"typed": {"listen": f"127.0.0.1:{free_port()}"},
                     "display": {"listen": f"127.0.0.1:{free_port()}"}},
        "routes": {"voice": {"input": {"text": "typed"},
                             "call": {"service": "tts", "method": "Synthesize",
                                      "text": "{text}"},
                             "outputs": [{"wav": str(folder / "spoken.wav"),
                                          "from": "speech"}]}},
        "agent": {"audit": str(folder / "audit.jsonl"),
                  "targets": {"display": {"channel": "display", "approval": "elicit",
                                          "approval_timeout_s": approval_timeout_s}}}}
    path = folder / "approval_pipeline.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


class RawStdio:
    """`oricf mcp ARGS` with pipes: lines written as given, every line it writes parsed."""

    def __init__(self, *args: str, log: Path) -> None:
        self.log = log
        with log.open("wb") as err:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "oricf", "mcp", *args], stdin=subprocess.PIPE,
                stdout=subprocess.PIPE, stderr=err, env=server_env(), start_new_session=True)
        self.received: queue.Queue[Any] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.received.put(json.loads(line))  # anything but JSON fails the test's wait
        self.received.put(None)

    def write(self, line: bytes) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(line.rstrip(b"\n") + b"\n")
        self.process.stdin.flush()

    def send(self, message: dict[str, Any]) -> None:
        self.write(json.dumps(message).encode())

    def next(self, timeout: float = 60.0) -> dict[str, Any]:
        """The next message the server writes; it must write one within the timeout."""
        try:
            message = self.received.get(timeout=timeout)
        except queue.Empty:
            raise AssertionError(f"no message within {timeout} s; "
                                 f"its log:\n{self.log.read_text()[-3000:]}") from None
        assert message is not None, f"the server ended; its log:\n{self.log.read_text()[-3000:]}"
        return dict(message)

    def reply(self, request_id: Any, timeout: float = 60.0) -> dict[str, Any]:
        """The answer to request_id, passing over notifications and requests from the
        server."""
        while True:
            message = self.next(timeout)
            if "method" not in message and message.get("id") == request_id:
                return message

    def initialize(self) -> None:
        self.send({"jsonrpc": "2.0", "id": "init", "method": "initialize", "params": {
            "protocolVersion": PROTOCOL, "capabilities": {"elicitation": {}},
            "clientInfo": {"name": "raw", "version": "0"}}})
        assert "result" in self.reply("init", timeout=120)
        self.send({"jsonrpc": "2.0", "method": "notifications/initialized"})

    def close(self) -> None:
        if self.process.stdin is not None:
            self.process.stdin.close()  # end of input: the server stops
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=10)
        self._reader.join(5)
        if self.process.stdout is not None:
            self.process.stdout.close()

    def __enter__(self) -> RawStdio:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
