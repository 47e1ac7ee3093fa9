"""The foxglove-sdk server's log lines, made safe: it logs what a viewer sent when it cannot
parse it (`Invalid message from ...: unknown variant ...`), words chosen by whoever is
connected. Each of its records is escaped and clipped like every string from outside
(oricf.logs.quoted), so a viewer cannot forge log lines, and a viewer's mistake (an
unparsable message, a subscription to a channel that does not exist, a message on a channel
the server never accepted) is a warning, not an error of the gateway, written at most once
per client per MISTAKE_LOG_INTERVAL_S with how many were suppressed, so a viewer that
repeats one cannot flood the log."""

from __future__ import annotations

import logging
import re

from oricf.gateway.throttle import Throttle
from oricf.logs import quoted

# The SDK's loggers (its Rust modules' names through pyo3-log); a filter applies only to the
# records of the logger it is on, so each is named.
SDK_LOGGERS = ("foxglove", "foxglove.runtime", "foxglove.websocket",
               "foxglove.websocket.server", "foxglove.websocket.connected_client",
               "foxglove.websocket.connected_client.poller")
# A viewer's mistakes as the SDK words them; `client` is its address where the line says it.
VIEWER_MISTAKE = re.compile(r"Invalid message from (?P<client>\S+): |"
                            r"Client (?P<subject>\S+) attempted to |"
                            r"Received message for unknown channel")
MAX_CHARS = 300
MISTAKE_LOG_INTERVAL_S = 10.0
MAX_CLIENTS_TRACKED = 256  # beyond it, clients quiet for an interval are forgotten


class SafeSdkRecords(logging.Filter):
    def __init__(self, throttle: Throttle) -> None:
        super().__init__()
        self.throttle = throttle

    def filter(self, record: logging.LogRecord) -> bool:
        text, note = record.getMessage(), ""
        mistake = VIEWER_MISTAKE.match(text)
        if mistake is not None:
            suppressed = self.throttle.admit(
                mistake.group("client") or mistake.group("subject") or "unnamed")
            if suppressed is None:
                return False
            if suppressed:
                note = (f" ({suppressed} more from this client suppressed in the last "
                        f"{self.throttle.interval_s:g} s)")
            if record.levelno > logging.WARNING:
                record.levelno, record.levelname = logging.WARNING, "WARNING"
        record.msg, record.args = "%s%s", (quoted(text, MAX_CHARS), note)
        return True


# Per client: its first mistake at once, then at most one per interval.
_THROTTLE = Throttle(MISTAKE_LOG_INTERVAL_S, max_keys=MAX_CLIENTS_TRACKED)


def make_sdk_logs_safe() -> None:
    """Idempotent: each SDK logger gets the filter once; all share one throttle."""
    for name in SDK_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, SafeSdkRecords) for f in logger.filters):
            logger.addFilter(SafeSdkRecords(_THROTTLE))
