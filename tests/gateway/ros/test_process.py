"""The gateway's allocator setting: frame-sized buffers come from the heap, not fresh mmaps."""

from __future__ import annotations

import subprocess
import sys

# Holds a fresh 1 MB buffer (a 640x480 bgr8 frame) and prints how many chunks glibc has
# mmap'd (mallinfo2().hblks): by default a first 1 MB allocation is mmap'd, and unmapped
# again on free; with the gateway's setting it comes from the heap, whose pages are reused.
# argv[1] == "keep" applies the setting first. Run in a child: pytest's own heap stays as is.
PROBE = """
import ctypes, sys
from oricf.gateway.ros.process import keep_freed_memory
class Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]
libc = ctypes.CDLL(None)
libc.mallinfo2.restype = Info
if sys.argv[1] == "keep":
    assert keep_freed_memory()
before = libc.mallinfo2().hblks
frame = bytearray(640 * 480 * 3 + 4096)
print(libc.mallinfo2().hblks - before)
"""


def mmapped_chunks(mode: str) -> int:
    result = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True,
                            text=True, check=True, timeout=60)
    return int(result.stdout)


def test_frame_sized_buffers_come_from_the_heap() -> None:
    assert mmapped_chunks("default") == 1  # the probe still sees glibc's default
    assert mmapped_chunks("keep") == 0
