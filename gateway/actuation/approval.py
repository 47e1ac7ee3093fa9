"""A person's yes or no on a text channel of the pipeline: the gateway writes

    approve 3? cmd_vel: {"linear": {"x": 0.2}}   (answer: yes 3 / no 3)

to every client of the channel and waits for `yes 3` or `no 3`; anything else, or nothing
before the target's approval_timeout_s, is a no. The channel must serve approvals alone.
"""

from __future__ import annotations

import itertools
import threading

from oricf.gateway.channels.clients import Client
from oricf.gateway.channels.server import TextChannel


class ChannelApprover:
    def __init__(self, channel: TextChannel) -> None:
        self._channel = channel
        self._ids = itertools.count(1)
        self._lock = threading.Lock()
        self._waiting: dict[int, tuple[threading.Event, list[bool]]] = {}
        channel.read_by(self._on_line)

    def ask(self, question: str, timeout_s: float) -> bool:
        number = next(self._ids)
        done, answer = threading.Event(), [False]
        with self._lock:
            self._waiting[number] = (done, answer)
        try:
            self._channel.send(f"approve {number}? {question} (answer: yes {number} / "
                               f"no {number})")
            done.wait(timeout_s)
            return answer[0]
        finally:
            with self._lock:
                self._waiting.pop(number, None)

    def _on_line(self, line: str, client: Client) -> None:
        words = line.strip().lower().split()
        # ASCII digits only: str.isdigit() also takes "²" and "①", which int() refuses
        if len(words) != 2 or words[0] not in ("yes", "no") or \
                not (words[1].isascii() and words[1].isdigit()):
            client.send("answer: yes N or no N")
            return
        with self._lock:
            waiting = self._waiting.get(int(words[1]))
        if waiting is None:
            client.send(f"nothing waits for approval {words[1]}")
            return
        done, answer = waiting
        answer[0] = words[0] == "yes"
        done.set()
