"""Keep freed memory in the process instead of returning it to the kernel at once.

Every camera frame passes through several buffers of its own size (the DDS sample, the
record, the request): about 1 MB each for 640x480 bgr8. glibc serves allocations over its
mmap threshold with fresh mmap'd pages and unmaps them on free, so each frame paid for
about 800 page faults (the kernel zeroing every page again): measured at 805 minor faults
per frame in `oricf bench gateway`, 4-7 with this setting. The same advice as for real-time
ROS 2 nodes: raise the mmap threshold and never trim, so the heap reuses its pages.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

log = logging.getLogger(__name__)

# glibc <malloc.h>
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 32 * 1024 * 1024  # glibc's maximum on 64-bit: buffers up to 32 MB reuse the heap
TRIM_THRESHOLD = 256 * 1024 * 1024  # keep up to this much free heap instead of trimming it


def keep_freed_memory() -> bool:
    """Sets the thresholds through mallopt; False (and nothing changed) without glibc."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        mallopt = ctypes.CDLL(name).mallopt
    except (OSError, AttributeError):  # not glibc (e.g. musl has no mallopt)
        log.debug("no mallopt in %s: memory thresholds left as they are", name)
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
                and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
