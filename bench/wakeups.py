"""Thread wake-ups: how often a process's threads wake, and what waking costs here.

Much of an offloaded gateway's CPU per frame is not work but waking up: every time one of
its threads blocks (on a socket, a condition, a timer) and is woken again, the kernel, and
on a virtual machine the hypervisor, charges the process for it. And the work that follows
a wake-up runs slower than the same work back to back, most likely because the caches and
TLBs it needs were refilled by other work (on a virtual machine, the host's too) while the
thread slept. The gateway works in short bursts (a frame
arrives, a reply arrives) with the camera's period in between, so both weigh far more on its
CPU per frame than on the detector's long bursts of inference. The gateway benchmark counts
the offloaded gateway's wake-ups per frame and measures both prices on this machine, so its
figures can be read against another machine's.
"""

from __future__ import annotations

import json
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

# The waker: writes one byte to the inherited socket `count` times, `rate` times a second.
_WAKER = """
import os, sys, time
fd, count, period = int(sys.argv[1]), int(sys.argv[2]), 1.0 / float(sys.argv[3])
next_at = time.monotonic()
for _ in range(count):
    next_at += period
    time.sleep(max(0.0, next_at - time.monotonic()))
    os.write(fd, b"x")
"""


def wakeups(pid: int, threads: str = "") -> int:
    """Times the threads of a process have blocked so far (each block ends in a wake-up):
    the sum of their voluntary context switches. `threads`: only those whose name starts
    so (e.g. "dds.ev." for Fast DDS's event threads)."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            if not (task / "comm").read_text().startswith(threads):
                continue
            status = (task / "status").read_text()
        except OSError:  # the thread ended meanwhile
            continue
        total += int(status.split("voluntary_ctxt_switches:")[1].split()[0])
    return total


def wakeup_cost(rate_hz: float, count: int = 50) -> float:
    """CPU seconds one wake-up costs a process on this machine: this thread blocks on a
    socket and another process wakes it rate_hz times a second; the median over `count`
    wake-ups (at a camera's pace, not back to back, as the gateway is woken)."""
    mine, theirs = socket.socketpair()
    waker = subprocess.Popen([sys.executable, "-c", _WAKER, str(theirs.fileno()), str(count),
                              str(rate_hz)], pass_fds=[theirs.fileno()])
    theirs.close()
    costs = []
    try:
        for _ in range(count):
            started = time.thread_time()
            mine.recv(1)
            costs.append(time.thread_time() - started)
    finally:
        mine.close()
        waker.wait()
    return statistics.median(costs)


def _burst() -> int:
    """A fixed short piece of Python work (tens of microseconds), like one step of the
    gateway's work per frame."""
    return len(json.dumps({str(i): i for i in range(100)}))


def _timed_burst() -> float:
    started = time.thread_time()
    _burst()
    return time.thread_time() - started


def idle_slowdown(idle_s: float, count: int = 30) -> tuple[float, float]:
    """Thread CPU seconds of one short burst of Python work back to back, and right after
    sleeping idle_s (the camera's period): medians over `count` bursts each."""
    for _ in range(5):
        _burst()
    back_to_back = statistics.median(_timed_burst() for _ in range(count))
    after_idle = []
    for _ in range(count):
        time.sleep(idle_s)
        after_idle.append(_timed_burst())
    return back_to_back, statistics.median(after_idle)
