"""Thread wake-ups: how often a process's threads wake, and what one wake-up costs here.

Much of an offloaded gateway's CPU per frame is not work but waking up: every time one of
its threads blocks (on a socket, a condition, a timer) and is woken again, the kernel, and
on a virtual machine the hypervisor, charges the process for it. The gateway benchmark
counts the offloaded gateway's wake-ups per frame and measures the price of one on this
machine, so its figures can be read against another machine's.
"""

from __future__ import annotations

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
