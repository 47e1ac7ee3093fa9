"""Whether the robot is speaking, and barge-in: what the speaker outputs, the microphone
inputs and the routes that stream speech share. No ROS, no audio library in here.

A speaker output tells `started()` when it begins to play and `stopped()` once its audio
has left the device. A microphone input with `while_speaking: mute` hears silence while
any speaker plays and for `MUTE_TAIL_S` after (the room's echo and the capture latency),
so the robot never takes its own answer for a question. One with `while_speaking:
barge_in` calls `interrupt()` when a new utterance starts: every speaker stops and drops
what it holds, the routes that make speech drop their pending items (listeners), and speech
asked for before that moment (`current(asked_at)` is False) is never played: a sentence
still being synthesized, an answer still being generated.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

log = logging.getLogger(__name__)

MUTE_TAIL_S = 0.3

Listener = Callable[[], None]


class Speaking:
    def __init__(self, mute_tail_s: float = MUTE_TAIL_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        # Held while speech is handed on, and while an interrupt clears it: a piece of
        # speech is either handed on before the interrupt (and cleared by it) or refused.
        self.lock = threading.RLock()
        self.clock = clock
        self.interrupts = 0
        self._mute_tail_s = mute_tail_s
        self._interrupted_at = float("-inf")
        self._playing = 0
        self._quiet_since = float("-inf")
        self._listeners: list[Listener] = []

    def on_interrupt(self, listener: Listener) -> None:
        with self.lock:
            self._listeners.append(listener)

    def interrupt(self, reason: str) -> None:
        """Barge-in: everything playing or pending stops, speech asked for until now is
        dropped."""
        with self.lock:
            self._interrupted_at = self.clock()
            self.interrupts += 1
            playing = self._playing
            for listener in self._listeners:
                listener()
        if playing:
            log.info("speech interrupted: %s", reason)

    def current(self, asked_at: float) -> bool:
        """Whether speech asked for at `asked_at` (a clock time) may still be played."""
        with self.lock:
            return asked_at > self._interrupted_at

    def started(self) -> None:
        with self.lock:
            self._playing += 1

    def stopped(self) -> None:
        with self.lock:
            self._playing = max(self._playing - 1, 0)
            if not self._playing:
                self._quiet_since = self.clock()

    @property
    def playing(self) -> bool:
        with self.lock:
            return self._playing > 0

    def muted(self) -> bool:
        """Whether a muted microphone hears silence now: a speaker plays, or stopped less
        than the tail ago."""
        with self.lock:
            return self._playing > 0 or self.clock() < self._quiet_since + self._mute_tail_s
