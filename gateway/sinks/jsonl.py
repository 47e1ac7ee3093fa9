"""Outputs that are not ROS topics: JSON lines on standard output or in a file.

One object per output value: {"route": ..., "time": unix seconds, FIELD: value}, where FIELD
is the output's `from`. Detections become objects with label, class_id, score, box, and
the track_id and velocity a `track` step gives them (null otherwise); images are not
written (use a topic, or an annotation file output, for those).
"""

from __future__ import annotations

import dataclasses
import json
import sys
import threading
import time
from typing import TYPE_CHECKING, Any, TextIO

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.components import ComponentContext, Sink, SinkKind
from oricf.gateway.values import Frame, Record

if TYPE_CHECKING:
    from oricf.gateway.config import OutputConfig


def jsonable(value: Any) -> Any:
    if isinstance(value, Frame):
        return {"image": f"{value.width}x{value.height} {value.encoding}"}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if hasattr(value, "item"):  # numpy scalars
        return value.item()
    return value


class JsonLines(Sink):
    """Every jsonl output of a pipeline; a file is opened once and appended to."""

    def __init__(self) -> None:
        self._files: dict[str, TextIO] = {}
        self._lock = threading.Lock()

    def write(self, route: str, output: OutputConfig, value: Any) -> None:
        assert output.jsonl is not None
        line = json.dumps({"route": route, "time": round(time.time(), 3),
                           output.source: jsonable(value)})
        with self._lock:
            out = self._stream(output.jsonl)
            out.write(line + "\n")
            out.flush()

    def _stream(self, target: str) -> TextIO:
        if target == "-":
            return sys.stdout
        if target not in self._files:
            self._files[target] = open(target, "a", encoding="utf-8")  # noqa: SIM115
        return self._files[target]

    def send(self, output: OutputConfig, value: Any, record: Record) -> None:
        self.write(str(record.get("route", "")), output, value)

    def close(self) -> None:
        with self._lock:
            for out in self._files.values():
                out.close()
            self._files.clear()


class JsonlOutput(Schema):
    jsonl: str | None = Field(
        None, description="JSON lines: '-' for standard output, or a file (appended to)")


def open_lines(context: ComponentContext) -> Sink:
    return JsonLines()


COMPONENT = SinkKind("jsonl", JsonlOutput, open_lines, rank=2)
