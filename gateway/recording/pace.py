"""When each message of a replay is due: the recorded pace scaled by the rate, gaps capped.

A recording's log times come from the machine that wrote it, or from whoever made the file:
two messages may be a second apart, or 31 years, or 2^64 nanoseconds. Played faithfully, a
long gap keeps the replay (and the gateway, which exits when the replay has ended) waiting
for as long, and a gap or a rate beyond what a float or a thread's timeout can hold would
end the replay thread with an OverflowError. So a gap longer than MAX_GAP_NS of recorded
time between a message and the latest before it is skipped, logged once per gap: the next
message plays at once and the pace goes on from there. The rate is checked against a range
before anything plays (MIN_RATE..MAX_RATE, or 0 for as fast as the routes take them).
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

from oricf.gateway.recording.recorder import RecordingError

log = logging.getLogger(__name__)

MIN_RATE = 0.01  # a hundred times slower than recorded
MAX_RATE = 1000.0
MAX_GAP_NS = 60 * 10**9  # of recorded time; a camera or a question is seldom quieter


def check_rate(rate: float) -> float:
    """The rate, if 0 or in MIN_RATE..MAX_RATE; else ValueError saying the range."""
    if rate == 0 or MIN_RATE <= rate <= MAX_RATE:
        return rate
    raise ValueError(f"must be 0 (as fast as the routes take the messages) or from "
                     f"{MIN_RATE:g} to {MAX_RATE:g}")


class Pace:
    """The wait before each message of one replay, in file order."""

    def __init__(self, path: Path, rate: float) -> None:
        try:
            self.rate = check_rate(rate)
        except ValueError as exc:
            raise RecordingError(f"{path}: rate {rate!r}: {exc}") from None
        self.path = path
        self.gaps_skipped = 0
        self._anchor: tuple[int, float] | None = None  # (log time, when it was played)
        self._latest = 0  # the latest log time so far

    def wait_s(self, log_time: int, now: float) -> float:
        """Seconds to wait (from `now`, a monotonic time) before playing a message."""
        if self.rate == 0:
            return 0.0
        if self._anchor is None or log_time - self._latest > MAX_GAP_NS:
            if self._anchor is not None:
                self._skip(log_time - self._latest)
            self._anchor = (log_time, now)
        self._latest = max(self._latest, log_time)
        first_log, first_played = self._anchor
        due = first_played + (log_time - first_log) / 1e9 / self.rate
        # Never longer than a thread's wait can be: even MAX_GAP_NS per message at MIN_RATE
        # for years of recording stays far below it, but a wait must never raise.
        return min(max(0.0, due - now), threading.TIMEOUT_MAX)

    def _skip(self, gap_ns: int) -> None:
        self.gaps_skipped += 1
        log.warning("%s: %s of recorded time without a message (more than %d s): skipped, "
                    "the next message plays at once", self.path, _duration(gap_ns),
                    MAX_GAP_NS // 10**9)


def _duration(ns: int) -> str:
    seconds = ns / 1e9
    if seconds < 3 * 86400:
        return f"{seconds:,.0f} s"
    return f"{seconds / 86400 / 365.25:,.1f} years"
