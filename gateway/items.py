"""What a source hands its route, and how it hears what became of it.

An item is a loader: called on the route's thread, it builds the record (so an item the
route's queue drops is never even converted). An item whose source waits for the outcome is
also an `Asker`, told once: `answered(record)` when its record went through the route (its
outputs sent: a control loop takes the chunk), `fail(message)` when it did not (a text
channel's client gets an `error:` line), `on_drop(reason)` when the queue dropped it unrun.
The route and the worker tell `asker_of(item)`; a plain loader hears nothing.
"""

from __future__ import annotations

from collections.abc import Callable

from oricf.gateway.values import Record

Loader = Callable[[], Record]
Submit = Callable[[Loader], None]   # hands a route an item, as a loader that builds its record


class Asker:
    """Told what became of an item; each by default hears nothing."""

    def answered(self, record: Record) -> None:
        """The item's record went through the route, its outputs sent."""

    def fail(self, message: str) -> None:
        """The item's record did not go through: why, as the asker may be told it."""

    def on_drop(self, reason: str) -> None:
        """The route's queue dropped the item before it ran: why."""


NOBODY = Asker()


def asker_of(item: object) -> Asker:
    """Who is told what became of `item`: the item itself when it is an Asker, else nobody."""
    return item if isinstance(item, Asker) else NOBODY
