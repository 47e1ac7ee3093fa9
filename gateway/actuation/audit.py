"""The audit trail of an agent: one JSON line per tool call or command, allowed or refused,
and Prometheus counters of the same (`oricf_agent_calls_total{tool,outcome}`).

Arguments are recorded clipped (an image is recorded by its size, never its bytes); numbers
JSON cannot hold (NaN, infinities) and integers beyond 64 bits as text, so a refused command
is recorded as refused whatever it held. A bearer token never reaches a tool's arguments,
so it never reaches this file.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from pathlib import Path
from typing import Any, TextIO

from prometheus_client import CollectorRegistry, Counter

from oricf.metrics import new_registry

log = logging.getLogger(__name__)

MAX_VALUE_CHARS = 500


def clipped(value: Any) -> Any:
    """A JSON-safe, bounded copy for the log: long text cut, bytes as their length."""
    if isinstance(value, dict):
        return {str(k)[:100]: clipped(v) for k, v in list(value.items())[:50]}
    if isinstance(value, list | tuple):
        return [clipped(v) for v in value[:50]]
    if isinstance(value, bytes | bytearray):
        return f"<{len(value)} bytes>"
    if isinstance(value, str):
        return value if len(value) <= MAX_VALUE_CHARS else f"{value[:MAX_VALUE_CHARS]}..."
    if isinstance(value, float) and not math.isfinite(value):  # JSON has no such number
        return "NaN" if math.isnan(value) else "Infinity" if value > 0 else "-Infinity"
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        return big_integer(value)
    if value is None or isinstance(value, bool | int | float):
        return value
    return clipped(str(value))


def big_integer(value: int) -> str:
    """An integer beyond 64 bits, as text (a reader of the log may take numbers as 64-bit
    floats): its digits, clipped; one too long to print, by its size."""
    try:
        return clipped(str(value))
    except ValueError:  # beyond Python's limit on digits printed
        return f"<integer of {value.bit_length()} bits>"


class AuditLog:
    """Thread-safe; `path` None keeps the counters only."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self.registry: CollectorRegistry = new_registry()
        self.calls = Counter("oricf_agent_calls", "Agent tool calls and commands by outcome",
                             ["tool", "outcome"], registry=self.registry)
        self._lock = threading.Lock()
        self._file: TextIO | None = None
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file = path.open("a", encoding="utf-8")
            log.info("agent audit log: %s", path)

    def record(self, tool: str, outcome: str, **details: Any) -> None:
        """outcome: ok, sent, clamped, refused, error, deadman."""
        self.calls.labels(tool, outcome).inc()
        if self._file is None:
            return
        entry = {"time": round(time.time(), 3), "tool": tool, "outcome": outcome,
                 **{k: clipped(v) for k, v in details.items()}}
        line = json.dumps(entry, ensure_ascii=True, allow_nan=False, default=str)
        with self._lock:
            self._file.write(line + "\n")
            self._file.flush()

    def counts(self) -> dict[str, int]:
        """tool/outcome -> calls, for `status`."""
        out: dict[str, int] = {}
        for metric in self.calls.collect():
            for sample in metric.samples:
                if sample.name.endswith("_total"):
                    key = f"{sample.labels['tool']}/{sample.labels['outcome']}"
                    out[key] = int(sample.value)
        return out

    def close(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None
