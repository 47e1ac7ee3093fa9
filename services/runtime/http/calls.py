"""Helpers for a service's HTTP routes: reading a JSON body, and running the blocking model
off the event loop while noticing that the client went away.

Model code is blocking (llama.cpp, CTranslate2) and checks a `still_wanted` callable between
steps, as over gRPC. Here that check raises Cancelled once the client has disconnected, so a
generation stops within a token of the client leaving.
"""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import AsyncGenerator, Callable, Iterator
from typing import Any, TypeVar

from starlette.concurrency import run_in_threadpool
from starlette.requests import Request

from oricf.errors import Cancelled, InvalidInput

T = TypeVar("T")


async def read_json(request: Request) -> dict[str, Any]:
    """The body as a JSON object; InvalidInput (400) naming what is wrong otherwise."""
    body = await request.body()
    if not body:
        raise InvalidInput("the request body is empty: send a JSON object")
    try:
        data = json.loads(body)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidInput(f"the request body is not valid JSON: {exc}") from None
    except RecursionError:
        raise InvalidInput("the request body is nested too deeply") from None
    if not isinstance(data, dict):
        raise InvalidInput(f"the request body must be a JSON object, not {type(data).__name__}")
    return data


class Presence:
    """Whether the client is still connected; checked from the model's thread."""

    def __init__(self) -> None:
        self._gone = threading.Event()

    def leave(self) -> None:
        self._gone.set()

    def still_wanted(self) -> None:
        if self._gone.is_set():
            raise Cancelled("the client went away; the work was stopped")


async def _watch(request: Request, presence: Presence) -> None:
    """Waits for the client's disconnect (the body has been read by then)."""
    while True:
        message = await request.receive()
        if message["type"] == "http.disconnect":
            presence.leave()
            return


async def run_blocking(request: Request, work: Callable[[Callable[[], None]], T]) -> T:
    """work(still_wanted) in a worker thread; still_wanted raises once the client left."""
    presence = Presence()
    # A task of its own rather than a task group: the work's exception reaches the caller
    # as it is, not wrapped in an ExceptionGroup.
    watcher = asyncio.ensure_future(_watch(request, presence))
    try:
        return await run_in_threadpool(work, presence.still_wanted)
    finally:
        watcher.cancel()


async def iterate_blocking(items: Iterator[T], presence: Presence) -> AsyncGenerator[T, None]:
    """A blocking iterator's items, each fetched in a worker thread. When the consumer stops
    (the client went away, the stream was cancelled), the iterator is closed here, after
    its current step: a generator's cleanup (the model's turn) runs at once."""
    end = object()
    try:
        while True:
            item = await run_in_threadpool(next, items, end)
            if item is end:
                return
            yield item  # type: ignore[misc]
    finally:
        presence.leave()
        close = getattr(items, "close", None)
        if close is not None:
            close()
