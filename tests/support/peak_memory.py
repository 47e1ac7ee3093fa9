"""How far this process's resident memory peaked over a piece of work: the kernel's
high-water mark (VmHWM) is reset first through /proc/self/clear_refs, so the peak of an
earlier test in the same process hides nothing."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

STATUS = Path("/proc/self/status")


def _status_kb(key: str) -> int:
    for line in STATUS.read_text().splitlines():
        if line.startswith(f"{key}:"):
            return int(line.split()[1])
    raise AssertionError(f"no {key} in {STATUS}")


@contextmanager
def peak_growth() -> Iterator[Callable[[], int]]:
    """Yields a function that says, in bytes, how far the peak rose above the memory
    resident at the start."""
    Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS
    start = _status_kb("VmRSS")
    yield lambda: (_status_kb("VmHWM") - start) * 1024
