"""Helpers for a service's HTTP routes: reading a JSON body, and running the blocking model
off the event loop while noticing that the client went away.

A JSON body may carry lone UTF-16 surrogates (`"\\ud800"`, or their bytes, which Python's
JSON decoder lets through): no text can be made of them (a tokenizer, a phonemizer and UTF-8
all refuse them), so a body with one anywhere, key or value, is refused here, naming where.

Model code is blocking (llama.cpp, CTranslate2) and checks a `still_wanted` callable between
steps, as over gRPC. Here that check raises Cancelled once the client has disconnected, so a
generation stops within a token of the client leaving.
"""

from __future__ import annotations

import asyncio
import json
import re
import threading
from collections.abc import AsyncGenerator, Callable, Iterator
from typing import Any, TypeVar

from starlette.concurrency import run_in_threadpool
from starlette.requests import Request

from oricf.errors import Cancelled, InvalidInput
from oricf.services.runtime.http.errors import InvalidParam

T = TypeVar("T")

SURROGATE = re.compile("[\ud800-\udfff]")


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
    where = lone_surrogate(data)
    if where is not None:
        raise InvalidParam(f"{where}: a lone UTF-16 surrogate (\\ud800-\\udfff without its "
                           f"pair) is not text; send valid Unicode", param=where)
    return data


def lone_surrogate(data: Any) -> str | None:
    """The path (`messages[0].content`) of a string, key or value, in parsed JSON
    that holds a lone surrogate; None if there is none. A loop, not recursion: the body
    may be nested as deeply as the JSON decoder allowed."""
    stack: list[tuple[str, Any]] = [("", data)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, str):
            if SURROGATE.search(value):
                return path or "body"
        elif isinstance(value, dict):
            for key, item in value.items():
                inner = f"{path}.{key}" if path else key
                if SURROGATE.search(key):
                    return f"{path}.(a key)" if path else "(a key)"
                stack.append((inner, item))
        elif isinstance(value, list):
            stack.extend((f"{path}[{i}]", item) for i, item in enumerate(value))
    return None


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
