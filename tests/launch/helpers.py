"""Real `oricf up` / `oricf demo` processes for the launcher tests, and process-table checks."""

from __future__ import annotations

import contextlib
import os
import queue
import random
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import yaml

from oricf.config import config_dir

STARTED = re.compile(r"started (\w+) \(pid (\d+)\)")


def private_ros_env() -> dict[str, str]:
    """A DDS domain of this test run's own, discovery on localhost only."""
    return {"ROS_DOMAIN_ID": str(random.randint(1, 100)),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def write_deployment(folder: Path, data: dict[str, Any], name: str = "deployment.yaml") -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(data))
    return path


def write_overlay(folder: Path, endpoints: dict[str, Any], name: str = "placement.yaml",
                  **sections: Any) -> Path:
    """A pipeline overlay: these endpoints (and other top-level sections)."""
    return write_deployment(folder, {"endpoints": endpoints, **sections}, name)


def service_entry(port: int, **extra: Any) -> dict[str, Any]:
    return {"listen": f"127.0.0.1:{port}", **extra}


def shipped_pipeline() -> str:
    return str(config_dir() / "pipelines" / "people_qa.yaml")


def group_members(pgid: int) -> list[int]:
    """Live (non-zombie) processes whose process group is pgid."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if fields[0] != "Z" and int(fields[2]) == pgid:
            members.append(int(entry.name))
    return members


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


class OricfCommand:
    """`python -m oricf ARGS` with its output collected line by line."""

    def __init__(self, *args: str, env: dict[str, str] | None = None) -> None:
        self.lines: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "oricf", *args], env={**os.environ, **(env or {})},
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            start_new_session=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line.rstrip("\n"))
            self._queue.put(line)

    def wait_for(self, pattern: str, timeout: float) -> re.Match[str]:
        """The first new output line matching pattern (fails if the process ends first)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self._queue.get(timeout=0.2)
            except queue.Empty:
                if self.process.poll() is not None and self._queue.empty():
                    break
                continue
            match = re.search(pattern, line)
            if match:
                return match
        raise AssertionError(f"no line matching {pattern!r}; output:\n{self.output}")

    @property
    def output(self) -> str:
        return "\n".join(self.lines)

    def started(self) -> dict[str, list[int]]:
        """Process name -> every pid the launcher reported starting it with."""
        pids: dict[str, list[int]] = {}
        for match in STARTED.finditer(self.output):
            pids.setdefault(match.group(1), []).append(int(match.group(2)))
        return pids

    def finish(self, timeout: float) -> int:
        code = self.process.wait(timeout=timeout)
        self._reader.join(timeout=5)
        return code

    def kill(self) -> None:
        """Test clean-up whatever happened: the launcher and every group it started (each
        child has a session of its own)."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait(timeout=10)
        for pids in self.started().values():
            for pid in pids:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(pid, signal.SIGKILL)
