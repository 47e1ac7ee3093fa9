"""Logging set-up, called once by each entry point (never at import)."""

from __future__ import annotations

import logging
import os
import sys
from typing import TextIO

FORMAT = "%(asctime)s %(levelname)-5s %(name)s: %(message)s"
# HTTP clients that log every request at INFO (the openai client's httpx): a line per
# language-model call would drown the log, so they say only what went wrong.
QUIET = ("httpx", "httpx2", "httpcore", "openai")


class CurrentStderr(logging.StreamHandler):  # type: ignore[type-arg]
    """Writes to whatever sys.stderr is when a line is logged, as logging's own last-resort
    handler does: a thread that logs after its caller replaced sys.stderr (a test harness, a
    daemon) must not write to a stream that has been closed since."""

    def __init__(self) -> None:
        logging.Handler.__init__(self)

    @property  # type: ignore[override]
    def stream(self) -> TextIO:
        return sys.stderr


def setup_logging(level: str | None = None) -> None:
    level_name = (level or os.environ.get("ORICF_LOG_LEVEL") or "INFO").upper()
    handler = CurrentStderr()
    handler.setFormatter(logging.Formatter(FORMAT, datefmt="%H:%M:%S"))
    logging.basicConfig(level=level_name, handlers=[handler], force=True)
    if logging.getLogger().level > logging.DEBUG:
        for name in QUIET:
            logging.getLogger(name).setLevel(logging.WARNING)


def quoted(value: object, limit: int = 200) -> str:
    """A string from outside (a recording, a camera, a client) made safe for a log line or
    an error that gets logged: quoted and escaped as Python's repr does (a newline cannot
    forge a second line, an escape sequence cannot recolour the terminal) and clipped, with
    the full length said, so a huge value cannot flood the log."""
    text = value if isinstance(value, str) else str(value)
    if len(text) <= limit:
        return repr(text)
    return f"{text[:limit]!r}... ({len(text):,} characters)"
