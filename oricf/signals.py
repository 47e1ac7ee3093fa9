"""Stopping on SIGTERM and SIGINT the same way in every long-running command."""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

log = logging.getLogger(__name__)


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An event set by SIGTERM or SIGINT; the previous handlers come back afterwards.
    Enter it in the main thread (Python runs signal handlers there)."""
    stop = threading.Event()

    def on_signal(signum: int, _frame: object) -> None:
        log.info("received %s: stopping", signal.Signals(signum).name)
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


@contextmanager
def interrupt_on_signals() -> Iterator[None]:
    """SIGINT and SIGTERM raise KeyboardInterrupt in the main thread, the first time only:
    the clean-up that follows is not cut short by a second Ctrl-C (it is logged). For
    commands whose stages block in many places (`oricf demo`), where one exception unwinds
    them all. The handlers are set whatever the process inherited: a shell starts a
    background job with SIGINT ignored, and Python then never raises KeyboardInterrupt."""
    stopping = False

    def on_signal(signum: int, _frame: object) -> None:
        nonlocal stopping
        name = signal.Signals(signum).name
        if stopping:
            log.warning("received %s: already stopping", name)
            return
        stopping = True
        log.info("received %s: stopping", name)
        raise KeyboardInterrupt

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
