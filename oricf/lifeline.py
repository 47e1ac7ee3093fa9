"""Child processes that follow their launcher: when the process that started them is gone,
however it went (SIGKILL included), they stop as if they had been sent SIGTERM.

The launcher keeps the write end of a pipe that it never writes to; each child inherits only
the read end (its number in ORICF_LIFELINE_FD) and watches it on a thread. The kernel closes
the write end when the launcher dies, so the child's read returns end-of-file: no polling,
no dependence on which thread forked the child (Linux's parent-death signal follows the
forking thread), and it works on every POSIX system.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time

log = logging.getLogger(__name__)

ENV = "ORICF_LIFELINE_FD"
# After the SIGTERM a child gives itself, how long its own stop may take before it kills
# its process group (itself and whatever it started).
STOP_GRACE_S = 10.0

_write_end: int | None = None
_read_end: int | None = None
_lock = threading.Lock()


def child_options() -> tuple[dict[str, str], tuple[int, ...]]:
    """(environment, pass_fds) for subprocess.Popen, so the child follows this process.

    One pipe serves every child this process starts; its write end is not inheritable, so
    no child (nor anything a child starts) holds it."""
    global _write_end, _read_end
    with _lock:
        if _read_end is None:
            _read_end, _write_end = os.pipe()
    return {ENV: str(_read_end)}, (_read_end,)


def follow_parent(grace_s: float = STOP_GRACE_S) -> bool:
    """In a child started with child_options(): stop when the launcher is gone. Returns
    whether there is a launcher to follow. Takes the variable out of the environment, so the
    child's own children do not watch a descriptor number that means nothing to them."""
    value = os.environ.pop(ENV, None)
    if value is None:
        return False
    try:
        fd = int(value)
        os.set_inheritable(fd, False)
    except (ValueError, OSError):
        log.warning("%s=%r is not an open descriptor: not following the launcher", ENV, value)
        return False
    threading.Thread(target=_watch, args=(fd, grace_s), name="lifeline", daemon=True).start()
    return True


def _watch(fd: int, grace_s: float) -> None:
    try:
        while os.read(fd, 1):  # nothing is ever written: only end-of-file returns
            pass
    except OSError:
        pass
    log.warning("the process that started this one is gone: stopping")
    _silence_output()
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(grace_s)
    log.error("still running %.0f s after the launcher went: killing it", grace_s)
    if os.getpgid(0) == os.getpid():  # a group of its own: what it started goes with it
        os.killpg(os.getpid(), signal.SIGKILL)
    os.kill(os.getpid(), signal.SIGKILL)


def _silence_output() -> None:
    """The launcher read this process's output: with it gone, every write would fail
    (EPIPE) and could derail the stop, so output goes nowhere from now on."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    for fd in (1, 2):
        os.dup2(devnull, fd)
    os.close(devnull)
