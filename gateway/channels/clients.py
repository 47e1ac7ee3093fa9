"""One client of a text channel (server.py): its writes, made on the channel's event
loop whatever thread sends, and the answers it still waits for, so that a client that
half-closes its connection after its last question is answered before it is closed.

A line reaches the client as one line of printable text: line breaks of any kind become
spaces, and the other control characters (ESC, NUL, the C1 set, DEL; all but tab) are
written as `\\xNN`, so text from a model or an agent cannot drive the terminal or display
that shows it.
"""

from __future__ import annotations

import asyncio
import logging
import time

log = logging.getLogger(__name__)

MAX_UNSENT_BYTES = 1 << 20
ESCAPED = {code: f"\\x{code:02x}" for code in (*range(0x20), 0x7F, *range(0x80, 0xA0))
           if code != ord("\t")}


def one_printable_line(line: str) -> str:
    """Line breaks (\\r, \\v, \\x1c, U+2028 and the rest) as spaces, other control
    characters escaped."""
    return " ".join(line.splitlines()).translate(ESCAPED)


class Client:
    """One connected client. `send` and `fail` may be called from any thread and never
    block; the rest runs on the channel's loop."""

    def __init__(self, writer: asyncio.StreamWriter, loop: asyncio.AbstractEventLoop,
                 host: str, port: int, channel: str) -> None:
        self.host = host
        self.peer = f"{host}:{port}"
        self.channel = channel
        self.open = True
        self.answered = asyncio.Event()  # no question of this client is waiting
        self.answered.set()
        self._waiting = 0
        self._writer = writer
        self._loop = loop
        self.heard_at = time.monotonic()  # when it last sent a line (or connected)

    def send(self, line: str, answer: bool = False) -> None:
        """A line to this client; `answer`: it answers one of the client's questions."""
        if self.open:
            data = (one_printable_line(line) + "\n").encode()
            try:
                self._loop.call_soon_threadsafe(self._deliver, data, answer)
            except RuntimeError:  # the loop has closed
                self.open = False

    def fail(self, message: str) -> None:
        """The question this client asked failed: it is told so instead of an answer."""
        self.send(f"error: {message}", answer=True)

    def asked(self) -> None:
        """On the loop: a question of this client went to the route."""
        self._waiting += 1
        self.answered.clear()

    def heard(self) -> None:
        """On the loop: the client sent a line."""
        self.heard_at = time.monotonic()

    def idle_s(self) -> float:
        return time.monotonic() - self.heard_at

    def reply(self, line: str) -> None:
        """On the loop itself (the channel's own messages), ahead of anything scheduled."""
        self._write((one_printable_line(line) + "\n").encode())

    def transport_closing(self) -> bool:
        """Whether nothing can reach the client any more (TLS closes both sides at once)."""
        return self._writer.transport.is_closing()

    def close(self) -> None:
        """No more lines; what was written still goes out before the connection closes."""
        self.open = False
        self.answered.set()
        self._writer.transport.close()

    def drop(self) -> None:
        """Cut off now: what was not sent yet is lost."""
        self.open = False
        self.answered.set()
        self._writer.transport.abort()

    def _deliver(self, data: bytes, answer: bool) -> None:
        self._write(data)
        if answer:
            self._waiting = max(0, self._waiting - 1)
            if not self._waiting:
                self.answered.set()

    def _write(self, data: bytes) -> None:
        # A client that stops reading is closed rather than buffered for without end.
        if self._writer.transport.get_write_buffer_size() > MAX_UNSENT_BYTES:
            log.warning("text channel: %s reads nothing; closing it", self.peer)
            self.drop()
        elif self.open:
            self._writer.write(data)
