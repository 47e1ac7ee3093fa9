"""Progress output for long waits (models loading): one line rewritten in place on a
terminal, an occasional line otherwise (logs, CI)."""

from __future__ import annotations

import threading
import time
from typing import TextIO

# Without a terminal, repeat a waiting message at most this often.
PLAIN_EVERY_S = 5.0


class ProgressLine:
    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self._lock = threading.Lock()
        self._open = False  # a rewritten line is on screen without its newline
        self._last_plain = 0.0

    def __call__(self, message: str, final: bool = False) -> None:
        """A passing state (`waiting ...`): rewritten in place or shown now and then;
        final: a line that stays."""
        if final:
            self.done(message)
            return
        with self._lock:
            if self.tty:
                self.stream.write("\r\033[K" + message)
                self._open = True
            elif time.monotonic() - self._last_plain >= PLAIN_EVERY_S:
                self._last_plain = time.monotonic()
                self.stream.write(message + "\n")
            self.stream.flush()

    def done(self, message: str) -> None:
        """A line that stays (`detector SERVING ...`)."""
        with self._lock:
            prefix = "\r\033[K" if self._open else ""
            self._open = False
            self.stream.write(prefix + message + "\n")
            self.stream.flush()
