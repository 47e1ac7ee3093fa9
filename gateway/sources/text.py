"""Lines of text as route inputs: standard input (`text: "-"`), or a text channel of the
pipeline (`text: NAME`, gateway.channels). Each non-empty line is one item of the route;
an answer written to the same channel goes back to the client that asked (`reply_to`), and
so does the error of a question the route could not answer (the route tells the question,
an oricf.gateway.items.Asker).
Standard input ends the route at its end; a channel serves until the gateway stops.
"""

from __future__ import annotations

import logging
import sys
import threading
from typing import TYPE_CHECKING, Any, TextIO

from pydantic import Field

from oricf.config import Schema
from oricf.gateway.channels.server import Channels, Client
from oricf.gateway.components import ComponentContext
from oricf.gateway.items import Asker
from oricf.gateway.sources.base import OnEnd, Source, SourceKind, Submit
from oricf.gateway.values import Record

if TYPE_CHECKING:
    from oricf.gateway.config import InputConfig

log = logging.getLogger(__name__)


class Question(Asker):
    """A line as the route's loader; its client is told if the route fails it or its
    queue drops it (an answer goes back through the channel's output, to `reply_to`)."""

    def __init__(self, line: str, client: Client | None) -> None:
        self.line = line
        self.client = client

    def __call__(self) -> Record:
        return {"text": self.line, "reply_to": self.client}

    def fail(self, message: str) -> None:
        if self.client is not None:
            self.client.fail(message)

    def on_drop(self, reason: str) -> None:
        self.fail(reason)


class TextSource:
    def __init__(self, route: str, config: InputConfig, submit: Submit, on_end: OnEnd,
                 channels: Channels, stdin: TextIO | None = None) -> None:
        assert config.text is not None
        self.route = route
        self.name = config.text
        self.lines = 0
        self._submit = submit
        self._on_end = on_end
        self._channels = channels
        self._stdin = stdin or sys.stdin
        self._thread = threading.Thread(target=self._read_stdin, daemon=True,
                                        name=f"text-{route}")

    def start(self) -> None:
        if self.name == "-":
            self._thread.start()
        else:
            self._channels.get(self.name).read_by(self._take)

    def stop(self, timeout: float = 5.0) -> None:
        # Standard input cannot be interrupted portably: its daemon thread ends with the
        # process; a channel is closed by its owner (Channels.close).
        pass

    def _take(self, line: str, client: Client | None = None) -> None:
        self.lines += 1
        self._submit(Question(line, client))

    def _read_stdin(self) -> None:
        for raw in self._stdin:
            line = raw.strip()
            if line:
                self._take(line)
        log.info("route %s: standard input ended after %d lines", self.route, self.lines)
        self._on_end(self.route)


class TextInput(Schema):
    text: str | None = Field(
        None, description="lines of text: '-' for standard input, or a channel's name")


def open_source(route: str, config: Any, submit: Submit, on_end: OnEnd,
                context: ComponentContext) -> Source:
    return TextSource(route, config, submit, on_end, context.channels)


COMPONENT = SourceKind("text", TextInput, lambda config: "text", open_source,
                       channel=lambda config: config.text, rank=4)
