"""The typed answer path: an item that is an Asker is told what became of it by the worker
(dropped) and the route (failed, answered), also when it carries a trace context."""

from __future__ import annotations

from opentelemetry import context as otel_context

from oricf.gateway.items import Asker, asker_of
from oricf.gateway.route import TracedLoader
from oricf.gateway.values import Record
from oricf.gateway.worker import RouteWorker


class Item(Asker):
    def __init__(self) -> None:
        self.told: list[tuple[str, object]] = []

    def __call__(self) -> Record:
        return {"text": "hello"}

    def answered(self, record: Record) -> None:
        self.told.append(("answered", record))

    def fail(self, message: str) -> None:
        self.told.append(("fail", message))

    def on_drop(self, reason: str) -> None:
        self.told.append(("dropped", reason))


class Ignores:
    """A route that does nothing with its items."""

    def process(self, item: object) -> None:
        pass


def test_a_traced_item_is_told_as_the_item_itself() -> None:
    item = Item()
    traced = TracedLoader(item, otel_context.get_current())
    asker_of(traced).answered({"x": 1})
    asker_of(traced).fail("no")
    assert item.told == [("answered", {"x": 1}), ("fail", "no")]
    assert asker_of(lambda: {}).answered({}) is None  # a plain loader: nobody is told


def test_the_worker_tells_an_item_it_drops_and_ignores_a_plain_one() -> None:
    worker: RouteWorker[object] = RouteWorker("test", Ignores(), "latest")
    first, second = Item(), Item()
    worker.submit(TracedLoader(first, otel_context.get_current()))
    worker.submit(second)          # the newest replaces the first, which is told
    worker.submit(lambda: {})      # ... and this replaces the second
    assert first.told == [("dropped", "too many questions waiting; this one was dropped")]
    assert len(second.told) == 1
    worker.stop()
