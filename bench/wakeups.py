"""Thread wake-ups: how often a process's threads wake, and what waking costs here.

Much of an offloaded gateway's CPU per frame is not work but waking up: every time one of
its threads blocks (on a socket, a condition, a timer) and is woken again, the kernel, and
on a virtual machine the hypervisor, charges the process for it. And short work that follows
a pause runs slower than the same work back to back, most likely because the caches and TLBs
it needs were refilled by other work (on a virtual machine, the host's too) in the meantime:
`idle_slowdown` times it after sleeping and after busy-waiting as long, and on a shared
virtual machine the two are about equally slow, so the price is the pause, not the wake-up.
The gateway works in short bursts (a frame arrives, a reply arrives) with the camera's
period in between, so both prices weigh far more on its CPU per frame than on the detector's
long bursts of inference. The gateway benchmark counts the offloaded gateway's wake-ups per
frame and measures both prices on this machine, so its figures can be read against another
machine's.
"""

from __future__ import annotations

import json
import socket
import statistics
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import NamedTuple

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
    return sum(count for name, count in wakeups_by_thread(pid).items()
               if name.startswith(threads))


def wakeups_by_thread(pid: int) -> Counter[str]:
    """wakeups() of each kind of thread, by name with its number dropped ("dds.ev.3" and
    "dds.ev.7" are both "dds.ev."), so that two counts of the same process subtract."""
    counts: Counter[str] = Counter()
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            status = (task / "status").read_text()
        except OSError:  # the thread ended meanwhile
            continue
        counts[name.rstrip("0123456789")] += int(
            status.split("voluntary_ctxt_switches:")[1].split()[0])
    return counts


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


class BurstTimes(NamedTuple):
    """Thread CPU seconds of one short burst of Python work (medians)."""

    back_to_back: float
    after_sleep: float  # right after the thread slept one pause
    after_busy: float  # right after it busy-waited one pause (no sleep, no wake-up)


def idle_slowdown(pause_s: float, count: int = 30) -> BurstTimes:
    """One short burst of Python work timed back to back, right after sleeping pause_s (the
    camera's period), and right after busy-waiting as long: medians over `count` bursts each.
    Busy-waiting keeps the thread on its CPU, so what it still loses is not the wake-up's."""
    for _ in range(5):
        _burst()
    back_to_back = statistics.median(_timed_burst() for _ in range(count))
    after_sleep, after_busy = [], []
    for _ in range(count):
        time.sleep(pause_s)
        after_sleep.append(_timed_burst())
        _busy_wait(pause_s)
        after_busy.append(_timed_burst())
    return BurstTimes(back_to_back, statistics.median(after_sleep),
                      statistics.median(after_busy))


def _busy_wait(seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def idle_note(burst: BurstTimes, period_s: float, work: str) -> None:
    """How much slower this machine runs short work after a pause of `period_s` (a camera's
    frame, a control loop's tick): `work` is what comes in such bursts."""
    pause, hot = f"{period_s * 1e3:.1f} ms", burst.back_to_back
    print(f"A short burst of Python work takes {hot * 1e6:.0f} us back to back, "
          f"{burst.after_sleep * 1e6:.0f} us after sleeping {pause} "
          f"({burst.after_sleep / hot:.0f}x) and {burst.after_busy * 1e6:.0f} us after "
          f"busy-waiting {pause} ({burst.after_busy / hot:.0f}x) on this machine: {work} is "
          f"such bursts.")
