"""`oricf gateway` in a process of its own, without ROS (importing rclpy fails there), with its
live view on a free loopback port: the view's address is read from the log. Its output and
its log are read as they come, into lists: a pipe nobody reads would fill and stall the
gateway."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

START_TIMEOUT_S = 120.0


@dataclass
class ViewedGateway:
    process: subprocess.Popen[str]
    url: str = ""
    out: list[str] = field(default_factory=list)
    log: list[str] = field(default_factory=list)

    def stop(self, timeout: float = 30) -> int:
        """SIGTERM, then the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        return self.process.wait(timeout)


def without_ros(folder: Path) -> dict[str, str]:
    """An environment where `import rclpy` fails."""
    fake = folder / "no_ros" / "rclpy"
    fake.mkdir(parents=True, exist_ok=True)
    (fake / "__init__.py").write_text("raise ImportError('rclpy must not be imported')\n")
    return {"PYTHONPATH": str(fake.parent), "PATH": "/usr/bin:/bin", "HOME": str(Path.home()),
            **{k: v for k, v in os.environ.items() if k.startswith("ORICF_")}}


def _read(stream: IO[str], into: list[str], url_found: threading.Event,
          gateway: ViewedGateway) -> None:
    for line in stream:
        into.append(line)
        found = re.search(r"live view at (ws://\S+)", line)
        if found:
            gateway.url = found[1]
            url_found.set()
    url_found.set()  # the process ended: no address will come


@contextmanager
def gateway_with_view(folder: Path, *args: str) -> Iterator[ViewedGateway]:
    """`oricf gateway ARGS --foxglove 127.0.0.1:0` running, its view's address known; killed
    on exit if it is still running."""
    process = subprocess.Popen(
        [sys.executable, "-m", "oricf", "gateway", *args, "--foxglove", "127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        env=without_ros(folder))
    gateway, found = ViewedGateway(process), threading.Event()
    assert process.stdout is not None and process.stderr is not None
    readers = [threading.Thread(target=_read, args=(stream, into, found, gateway), daemon=True)
               for stream, into in ((process.stdout, gateway.out),
                                    (process.stderr, gateway.log))]
    for reader in readers:
        reader.start()
    try:
        found.wait(START_TIMEOUT_S)
        assert gateway.url, "no live view address; the log:\n" + "".join(gateway.log)[-3000:]
        yield gateway
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=10)
        for reader in readers:
            reader.join(timeout=10)
