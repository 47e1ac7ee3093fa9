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
import threading
import time

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


class MistakeThrottle:
    """Per client: the first mistake at once, then at most one per interval."""

    def __init__(self, interval_s: float = MISTAKE_LOG_INTERVAL_S) -> None:
        self.interval_s = interval_s
        self._lock = threading.Lock()
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def admit(self, client: str) -> int | None:
        """None to suppress this one; else how many of the client's were suppressed before."""
        now = time.monotonic()
        with self._lock:
            last = self._last.get(client)
            if last is not None and now - last < self.interval_s:
                self._suppressed[client] = self._suppressed.get(client, 0) + 1
                return None
            if len(self._last) >= MAX_CLIENTS_TRACKED:
                self._forget_quiet(now)
            self._last[client] = now
            return self._suppressed.pop(client, 0)

    def _forget_quiet(self, now: float) -> None:
        for client, last in list(self._last.items()):
            if now - last >= self.interval_s:
                del self._last[client]
                self._suppressed.pop(client, None)


class SafeSdkRecords(logging.Filter):
    def __init__(self, throttle: MistakeThrottle) -> None:
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


_THROTTLE = MistakeThrottle()


def make_sdk_logs_safe() -> None:
    """Idempotent: each SDK logger gets the filter once; all share one throttle."""
    for name in SDK_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, SafeSdkRecords) for f in logger.filters):
            logger.addFilter(SafeSdkRecords(_THROTTLE))
