"""Process settings for a gateway that handles a camera frame every few milliseconds.

- Freed memory stays in the process. Every camera frame passes through several buffers of
  its own size (the DDS sample, the record, the request). glibc serves allocations over its
  mmap threshold with fresh mmap'd pages and unmaps them on free, so each frame paid for a
  page fault per page (the kernel zeroing every page again). The same advice as for
  real-time ROS 2 nodes: raise the mmap threshold and never trim, so the heap reuses its
  pages.
- gRPC calls wait for their replies in the calling thread. By default grpcio hands every
  reply through its EventEngine thread pool, which wakes several of its threads per call;
  with the `event_engine_client` experiment off, the thread that makes a call polls its own
  socket. gRPC reads GRPC_EXPERIMENTS once, when it loads, so this must run before anything
  imports grpc; a GRPC_EXPERIMENTS the user set is left alone.

docs/benchmarks.md gives what each saves per frame (`oricf bench gateway`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import sys

log = logging.getLogger(__name__)

# glibc <malloc.h>
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 32 * 1024 * 1024  # glibc's maximum on 64-bit: buffers up to 32 MB reuse the heap
TRIM_THRESHOLD = 256 * 1024 * 1024  # keep up to this much free heap instead of trimming it
CALLING_THREAD_POLLS = "-event_engine_client"


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


def poll_in_calling_thread() -> None:
    """Turns grpcio's EventEngine client off, unless the user set GRPC_EXPERIMENTS or grpc
    is already loaded."""
    if "GRPC_EXPERIMENTS" in os.environ:
        return
    if "grpc" in sys.modules:
        log.debug("grpc is already loaded: its client keeps polling in the EventEngine")
        return
    os.environ["GRPC_EXPERIMENTS"] = CALLING_THREAD_POLLS
