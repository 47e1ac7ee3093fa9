"""The Gateway lifecycle on a real pipeline (people_video on vtest.avi, the real detector,
a live view): nothing runs before activate, everything started stops on deactivate, and a
part that cannot start stops the parts started before it."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from oricf.gateway.host.gateway import Gateway, LifecycleError
from oricf.gateway.values import Record
from tests.gateway.live_view.support import Kept, video_pipeline
from tests.support.services import RunningService
from tests.support.waiting import wait_for

OURS = ("route-", "video-")  # the threads of a route's worker and of a video source


def our_threads() -> list[str]:
    return sorted(t.name for t in threading.enumerate() if t.name.startswith(OURS))


def test_nothing_runs_before_activate_and_nothing_after_deactivate(
        detector: RunningService) -> None:
    gateway = Gateway(video_pipeline(detector.address))
    with pytest.raises(LifecycleError, match="not configured"):
        gateway.activate()
    gateway.configure()
    records: list[Record] = []
    route = gateway.pipeline.routes["people"]
    route.watchers.append(Kept(records))
    time.sleep(0.5)  # a started source would have read frames by now
    assert (our_threads(), records, gateway.live_view) == ([], [], None)
    gateway.activate()
    try:
        assert our_threads() == ["route-people", "video-people"]
        assert gateway.live_view is not None and gateway.live_view.url.startswith("ws://")
        wait_for(lambda: len(records) >= 3, timeout=30)
        assert all("count" in record for record in records)
    finally:
        gateway.deactivate()
        gateway.cleanup()
    assert (our_threads(), gateway.live_view) == ([], None)
    gateway.deactivate()  # a second stop has nothing left to stop
    gateway.cleanup()


def test_a_part_that_cannot_start_stops_the_parts_started_before_it(
        detector: RunningService) -> None:
    """The live view's port is taken: activate fails, and the route worker started before
    the live view is stopped; the sources, started after it, never start."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        gateway = Gateway(video_pipeline(detector.address, {"listen": f"127.0.0.1:{port}"}))
        gateway.configure()
        try:
            with pytest.raises(Exception, match=str(port)):
                gateway.activate()
            assert our_threads() == []
        finally:
            gateway.cleanup()
