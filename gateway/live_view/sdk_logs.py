"""The foxglove-sdk server's log lines, made safe: it logs what a viewer sent when it cannot
parse it (`Invalid message from ...: unknown variant ...`), words chosen by whoever is
connected. Each of its records is escaped and clipped like every string from outside
(oricf.logs.quoted), so a viewer cannot forge log lines or flood the log, and a viewer's
mistake is a warning, not an error of the gateway."""

from __future__ import annotations

import logging

from oricf.logs import quoted

# The SDK's loggers (its Rust modules' names through pyo3-log); a filter applies only to the
# records of the logger it is on, so each is named.
SDK_LOGGERS = ("foxglove", "foxglove.runtime", "foxglove.websocket",
               "foxglove.websocket.server", "foxglove.websocket.connected_client",
               "foxglove.websocket.connected_client.poller")
VIEWER_MISTAKES = ("Invalid message from", "attempted to")
MAX_CHARS = 300


class SafeSdkRecords(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        if text.startswith(VIEWER_MISTAKES) and record.levelno > logging.WARNING:
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        record.msg, record.args = "%s", (quoted(text, MAX_CHARS),)
        return True


def make_sdk_logs_safe() -> None:
    """Idempotent: each SDK logger gets the filter once."""
    for name in SDK_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, SafeSdkRecords) for f in logger.filters):
            logger.addFilter(SafeSdkRecords())
