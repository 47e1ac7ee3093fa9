"""The batcher on its own, around a plain function: errors stay with their item, a failed
run fails its batch only, and close() runs what waits and refuses what comes after."""

from __future__ import annotations

import threading

import pytest

from oricf.errors import InvalidInput, NotReady
from oricf.services.runtime.batching import Batcher, BatchingSettings

HOLD = BatchingSettings(max_batch_size=2, max_queue_delay_ms=10_000)


def halves(items: list[int]) -> list[float | Exception]:
    return [InvalidInput(f"{i} is odd") if i % 2 else i / 2 for i in items]


def test_an_item_error_is_its_own() -> None:
    batcher: Batcher[int, float] = Batcher("halves", HOLD, halves, 100)
    odd, even = batcher.submit(3), batcher.submit(8)  # two items: the batch is full
    assert even.result() == 4
    with pytest.raises(InvalidInput, match="3 is odd"):
        odd.result()
    assert batcher.snapshot()[0] == {2: 1}
    batcher.close()


def test_a_failed_run_fails_its_batch_and_the_batcher_goes_on() -> None:
    calls: list[list[int]] = []

    def flaky(items: list[int]) -> list[int | Exception]:
        calls.append(items)
        if len(calls) == 1:
            raise RuntimeError("the runtime fell over")
        return items

    batcher: Batcher[int, int] = Batcher("flaky", HOLD, flaky, 100)
    first = [batcher.submit(i) for i in (1, 2)]
    for ticket in first:
        with pytest.raises(RuntimeError, match="fell over"):
            ticket.result()
    second = [batcher.submit(i) for i in (3, 4)]
    assert [t.result() for t in second] == [3, 4]
    batcher.close()


def test_close_runs_what_waits_and_refuses_what_comes_after() -> None:
    started = threading.Event()

    def run(items: list[int]) -> list[int]:
        started.set()
        return items

    batcher: Batcher[int, int] = Batcher("drain", HOLD, run, 100)
    waiting = batcher.submit(7)  # alone: without close() it would wait 10 s for a partner
    assert not started.is_set()
    batcher.close()
    assert waiting.result() == 7
    with pytest.raises(NotReady, match="shutting down"):
        batcher.submit(8)
