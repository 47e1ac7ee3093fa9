"""The gRPC side of batching, for servicers: a call's item into a batcher and its result back.

The call's deadline becomes the ticket's (a request whose caller has given up never runs),
the call's end takes the item out of the queue, and a refusal for a full queue carries the
same `grpc-retry-pushback-ms` trailer as a refusal by the call limit.
"""

from __future__ import annotations

import time
from typing import Any, TypeVar

import grpc

from oricf.errors import Overloaded
from oricf.services.runtime.batching import Batcher
from oricf.services.runtime.limits import PUSHBACK_KEY

T = TypeVar("T")


def run_batched(batcher: Batcher[T, Any], item: T, context: grpc.ServicerContext | None,
                cancel: bool = True) -> Any:
    """item's result through the batcher. cancel=False for the frames of a stream: a
    callback per frame would live as long as the stream; its deadline still holds."""
    remaining = context.time_remaining() if context is not None else None
    deadline = None if remaining is None else time.monotonic() + remaining
    try:
        ticket = batcher.submit(item, deadline)
    except Overloaded as exc:
        if context is not None and exc.retry_after_ms is not None:
            context.set_trailing_metadata(((PUSHBACK_KEY, str(exc.retry_after_ms)),))
        raise
    if cancel and context is not None:
        context.add_callback(ticket.cancel)
    return ticket.result()
