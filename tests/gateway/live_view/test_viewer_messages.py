"""What a viewer sends that the live view does not take: messages on channels of its own,
which it never advertised (the view offers no client publishing). The protocol's own client
sends thousands; the gateway logs a few warnings that count them, never an error for each,
and goes on serving that viewer."""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Iterator

import pytest

from oricf.gateway.listeners import LiveViewConfig
from oricf.gateway.live_view.front import REFUSAL_LOG_INTERVAL_S
from oricf.gateway.live_view.view import LiveView
from tests.gateway.live_view.viewers import publishing_client

SENT = 5000
SECONDS = 60.0  # at most: the viewer leaves once served


@pytest.fixture()
def view() -> Iterator[LiveView]:
    """A live view with a product that changes every 20 ms."""
    view = LiveView(LiveViewConfig(listen="127.0.0.1:0"))
    view.start()
    stop = threading.Event()

    def feed() -> None:
        count = 0
        while not stop.wait(0.02):
            count += 1
            view.show_product("people_count", count % 7)

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        yield view
    finally:
        stop.set()
        feeder.join()
        view.stop()


def wait_for_no_viewers(view: LiveView) -> None:
    deadline = time.monotonic() + 10
    while view.front is not None and view.front.viewers:
        assert time.monotonic() < deadline, f"{view.front.viewers} viewers still held"
        time.sleep(0.01)


def test_a_viewers_messages_on_its_own_channels_are_a_few_warnings(
        view: LiveView, caplog: pytest.LogCaptureFixture) -> None:
    started = time.monotonic()
    with caplog.at_level(logging.INFO):
        got = publishing_client(view.url, SENT, SECONDS)
        wait_for_no_viewers(view)  # the relay has counted everything the viewer sent
    elapsed = time.monotonic() - started
    assert any("sent" in line and line["sent"] == SENT for line in got.lines)
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert not errors, (len(errors), errors[:3])
    assert got.messages["/products/people_count"]  # served all along
    told = [r for r in caplog.records if "on channels of its own" in r.getMessage()]
    assert all(r.levelno == logging.WARNING for r in told)
    # the first at once, one per interval at most, the rest when the viewer left
    assert 1 <= len(told) <= 2 + elapsed / REFUSAL_LOG_INTERVAL_S, [r.getMessage() for r in told]
    counted = [int(re.search(r"sent (\d+) message", r.getMessage())[1]) for r in told]  # type: ignore[index]
    assert sum(counted) == SENT, counted
