"""How the gateway's gRPC calls wait for their replies.

By default grpcio hands every reply through its EventEngine thread pool, which wakes
several of its threads per call: with a camera frame every 100 ms that was about ten
thread wake-ups per Detect call. With the `event_engine_client` experiment off, the
thread that makes a call polls its own socket, and the pool wakes about four times per
call. `oricf bench gateway` measured about 0.3 ms less robot CPU per frame (2.2 against
2.5 ms, grpcio 1.85).

gRPC reads GRPC_EXPERIMENTS once, when it loads, so this must run before anything imports
grpc; a GRPC_EXPERIMENTS the user set is left alone.
"""

from __future__ import annotations

import logging
import os
import sys

log = logging.getLogger(__name__)

CALLING_THREAD_POLLS = "-event_engine_client"


def poll_in_calling_thread() -> None:
    if "GRPC_EXPERIMENTS" in os.environ:
        return
    if "grpc" in sys.modules:
        log.debug("grpc is already loaded: its client keeps polling in the EventEngine")
        return
    os.environ["GRPC_EXPERIMENTS"] = CALLING_THREAD_POLLS
