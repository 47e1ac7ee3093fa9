"""A process's memory as the kernel counts it (/proc/PID/status), and how far this
process's resident memory peaked over a piece of work: the kernel's high-water mark (VmHWM)
is reset first through /proc/self/clear_refs, so the peak of an earlier test in the same
process hides nothing."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path


def memory_kb(pid: int | str, key: str) -> int:
    """A memory figure of a process (`self`: this one) in kB, e.g. VmRSS or VmHWM."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{key}:"):
            return int(line.split()[1])
    raise AssertionError(f"no {key} for process {pid}")


@contextmanager
def peak_growth() -> Iterator[Callable[[], int]]:
    """Yields a function that says, in bytes, how far the peak rose above the memory
    resident at the start."""
    Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS
    start = memory_kb("self", "VmRSS")
    yield lambda: (memory_kb("self", "VmHWM") - start) * 1024
