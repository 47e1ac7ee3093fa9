"""Outputs as lines of text: standard output (`text: "-"`) or a text channel, where a value
goes back to the client whose line started the record (else to every client)."""

from __future__ import annotations

import json
import sys
import threading
from typing import TYPE_CHECKING, Any

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.channels.server import Channels
from oricf.gateway.components import ComponentContext, Sink, SinkKind
from oricf.gateway.sinks.jsonl import jsonable
from oricf.gateway.values import Record

if TYPE_CHECKING:
    from oricf.gateway.config import OutputConfig


def as_line(value: Any) -> str:
    if isinstance(value, str):
        return value
    return json.dumps(jsonable(value))


class TextLines(Sink):
    def __init__(self, channels: Channels) -> None:
        self._channels = channels
        self._lock = threading.Lock()

    def send(self, output: OutputConfig, value: Any, record: Record) -> None:
        assert output.text is not None
        line = as_line(value).replace("\n", " ")
        if output.text == "-":
            with self._lock:
                sys.stdout.write(line + "\n")
                sys.stdout.flush()
        else:
            self._channels.get(output.text).send(line, record.get("reply_to"))

    def close(self) -> None:
        """The pipeline closes its channels."""


class TextOutput(Schema):
    text: str | None = Field(
        None, description="the value as a line of text: '-' for standard output, or a channel")


def open_lines(context: ComponentContext) -> Sink:
    return TextLines(context.channels)


COMPONENT = SinkKind("text", TextOutput, open_lines, channel=lambda output: output.text,
                     rank=3)
