"""Route workers: newest-frame slot with drop counting, bounded queues, errors contained."""

from __future__ import annotations

import logging
import threading

import pytest

from oricf.gateway.throttle import ThrottledLog
from oricf.gateway.worker import RouteWorker


class Blocked:
    """A route that keeps each item once released."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.handled: list[int] = []

    def process(self, item: int) -> None:
        self.release.wait(5)
        self.handled.append(item)


class Threads:
    """A route that notes the thread each item is handled in."""

    def __init__(self) -> None:
        self.names: list[str] = []

    def process(self, item: int) -> None:
        self.names.append(threading.current_thread().name)


class FailsOnOne:
    """A route that raises on item 1 and keeps the others."""

    def __init__(self) -> None:
        self.handled: list[int] = []

    def process(self, item: int) -> None:
        if item == 1:
            raise RuntimeError("boom")
        self.handled.append(item)


def blocked_worker(mode: str, size: int = 8) -> tuple[RouteWorker[int], list[int],
                                                         threading.Event]:
    route = Blocked()
    worker: RouteWorker[int] = RouteWorker("test", route, mode, size)
    worker.start()
    return worker, route.handled, route.release


def test_latest_keeps_only_the_newest_frame_while_busy() -> None:
    worker, handled, release = blocked_worker("latest")
    worker.submit(0)
    assert not worker.idle(0.2)  # 0 is being handled (blocked)
    for item in range(1, 6):
        worker.submit(item)
    release.set()
    assert worker.idle(5)
    worker.stop()
    assert handled == [0, 5]
    assert (worker.stats.received, worker.stats.dropped, worker.stats.handled) == (6, 4, 2)


def test_items_handled_in_the_callers_thread_are_counted_with_the_missed_ones() -> None:
    threads = Threads()
    worker: RouteWorker[int] = RouteWorker("camera", threads)
    worker.handle_here(0)
    worker.handle_here(1, missed=3)  # a camera thread: DDS replaced three frames meanwhile
    assert threads.names == [threading.current_thread().name] * 2
    assert (worker.stats.received, worker.stats.dropped, worker.stats.handled) == (5, 3, 2)
    assert worker.idle(0)


def test_queue_keeps_order_and_drops_the_oldest_when_full() -> None:
    worker, handled, release = blocked_worker("queue", size=3)
    worker.submit(0)
    assert not worker.idle(0.2)
    for item in range(1, 6):
        worker.submit(item)
    release.set()
    assert worker.idle(5)
    worker.stop()
    assert handled == [0, 3, 4, 5]
    assert worker.stats.dropped == 2


def test_an_exception_does_not_stop_the_worker(caplog: pytest.LogCaptureFixture) -> None:
    route = FailsOnOne()
    worker: RouteWorker[int] = RouteWorker("test", route, "queue")
    worker.start()
    for item in range(3):
        worker.submit(item)
    assert worker.idle(5)
    worker.stop()
    assert route.handled == [0, 2]
    assert "route test: unexpected error" in caplog.text


def test_throttled_log_suppresses_repeats(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    throttle = ThrottledLog(logging.getLogger("t"), 10.0, clock=lambda: now[0])
    assert throttle.error("a", "service down")
    assert not throttle.error("a", "service down")
    assert throttle.error("b", "another problem")  # other keys are not held back
    now[0] = 11.0
    assert throttle.error("a", "service down")
    messages = [r.getMessage() for r in caplog.records]
    assert messages == ["service down", "another problem",
                        "service down (1 similar suppressed in the last 10 s)"]



@pytest.mark.parametrize("mode", ["latest", "queue"])
def test_waiting_for_room_drops_nothing(mode: str) -> None:
    worker, handled, release = blocked_worker(mode, size=3)
    worker.submit(0)
    assert not worker.idle(0.2)  # 0 is being handled (blocked)
    room = 1 if mode == "latest" else 3
    for item in range(1, room + 1):
        assert worker.wait_room(1)
        worker.submit(item)
    assert not worker.wait_room(0.2)  # full: a replay at --rate 0 waits here
    release.set()
    for item in range(room + 1, 20):
        assert worker.wait_room(5)
        worker.submit(item)
    assert worker.idle(5)
    worker.stop()
    assert handled == list(range(20)) and worker.stats.dropped == 0
