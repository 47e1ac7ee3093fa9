"""Streams answered message by message (the Policy service's ActStream, reflection's
ServerReflectionInfo): a call slot only while a message is answered, and a time limit on
silence.

A robot keeps such a stream open and sends an observation per control step; between two it
costs the service nothing but a thread. Counting the whole stream as a call would let a few
quiet streams hold every slot and refuse everyone else's calls, so a message stream takes a
call slot when a message arrives and gives it back when the servicer asks for the next one
(it answers each before reading the next). Open message streams are bounded on their own
(the server keeps a thread for each, beside those of its calls), and a stream that sends
nothing for `idle_s` is closed, so quiet ones cannot keep new streams out for long.
Reflection streams are exempt from the call limit, as health checks are, but hold a thread
as long as they are open just the same: they are bounded and timed the same way, with a few
threads of their own.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

from oricf.errors import DeadlineExceeded, Overloaded
from oricf.services.runtime.limits import CallLimit

T = TypeVar("T")


@dataclass(frozen=True)
class MessageStreams:
    """A service's streaming RPCs that are answered message by message."""

    methods: frozenset[str]  # full method paths: "/oricf.v1.Policy/ActStream"
    idle_s: float  # a stream that sends nothing this long is closed
    key: str  # the config key idle_s comes from, for the message that closes a stream


@dataclass(frozen=True)
class OpenStreams:
    """Streams of one kind that are open: at most `open.limit` at once, each closed after
    idle_s without a request."""

    open: CallLimit  # a slot per open stream
    idle_s: float
    key: str  # the config key idle_s comes from
    what: str  # what a refusal says there are too many of: "streams open"


def per_message(requests: Iterator[Any], parse: Callable[[bytes], T], limit: CallLimit | None
                ) -> Iterator[T]:
    """Each request parsed, holding a call slot of `limit` (None: exempt, none) until the
    next is asked for; Overloaded (the call ends with pushback) when none is free as a
    request arrives."""
    for data in requests:  # waiting here holds no slot
        if limit is None:
            yield parse(data)
            continue
        if not limit.try_enter():
            wait_ms = limit.pushback_ms()
            raise Overloaded(f"the service is busy ({limit.limit} calls in progress); "
                             f"retry in {wait_ms} ms", wait_ms)
        try:
            yield parse(data)
        finally:
            limit.leave()


def idle_bounded(requests: Iterator[T], idle_s: float, key: str) -> Iterator[T]:
    """The requests, read by a thread of their own so that a silence can be timed:
    DeadlineExceeded once none has come for idle_s after the last was taken. At most two
    are read ahead of the one taken, so a client that sends faster than it is answered is
    still pushed back by gRPC's flow control."""
    ready: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=1)
    done = threading.Event()
    reader = threading.Thread(target=_read, args=(requests, ready, done), daemon=True,
                              name="stream-reader")
    reader.start()
    try:
        while True:
            try:
                kind, value = ready.get(timeout=idle_s)
            except queue.Empty:
                raise DeadlineExceeded(f"nothing was sent for {idle_s:g} s; the stream is "
                                       f"closed ({key})") from None
            if kind == "end":
                return
            if kind == "error":
                raise value
            yield value
    finally:
        done.set()  # the call is over: the reader must not wait for room in the queue


def hand_over(ready: queue.Queue[T], item: T, done: threading.Event) -> bool:
    """Puts `item` for the call's thread, waiting for room while the call lasts; False once
    the call is over (`done`), so a stream's reader never waits on a queue nobody empties."""
    while not done.is_set():
        try:
            ready.put(item, timeout=0.1)
            return True
        except queue.Full:
            continue
    return False


def _read(requests: Iterator[Any], ready: queue.Queue[tuple[str, Any]],
          done: threading.Event) -> None:
    """Hands each request over; the end of the stream or its error last. Once the call has
    ended, gRPC ends the request iterator too, so the thread never outlives it for long."""
    def put(item: tuple[str, Any]) -> bool:
        return hand_over(ready, item, done)

    try:
        for request in requests:
            if not put(("request", request)):
                return
    except Exception as exc:  # the caller went away or the stream broke
        put(("error", exc))
        return
    put(("end", None))
