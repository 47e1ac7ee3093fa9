"""Gateway and edge service on two hosts (network namespaces) joined by a degraded link:
20 Mbit/s, 2% random loss, 50 ms +- 10 ms delay; then the link is cut until the route has
failed over and counted on the fallback, and comes back. The people route keeps counting
throughout: on the edge, on the onboard fallback while the link is down, and on the edge
again once its health check says SERVING."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from oricf.bench.link import EDGE_PORT, feed, oricf, served
from oricf.bench.netns import EdgeHost, edge_host
from oricf.bench.relay import DelayRelay
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame
from tests.gateway.test_pipeline import Outputs, pipeline_config
from tests.support.data import video_frames
from tests.support.services import RunningService


@contextmanager
def edge_detector(edge: EdgeHost) -> Iterator[str]:
    address = f"{edge.address}:{EDGE_PORT}"
    with served(edge.exec_argv(oricf("serve", "detector", "--listen", address)), address):
        yield address


def feed_until(pipeline: Pipeline, frames: list[Frame], done: Callable[[], bool],
               what: str, timeout: float = 60) -> None:
    """Camera frames at the link benchmark's rate until done(), however long that takes
    over this link; the timeout only keeps a broken run from hanging."""
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, what
        feed(pipeline, frames, 0.5)


def test_counting_survives_a_degraded_and_cut_link(detector: RunningService) -> None:
    frames = [Frame.from_pixels(f) for f in video_frames([0, 80, 160, 400])]
    onboard = detector  # the session's: the fallback on this host
    with edge_host() as edge, edge_detector(edge) as remote:
        host, _, port = remote.rpartition(":")
        relay = DelayRelay((host, int(port)), delay_s=0.05, jitter_s=0.01)
        edge.degrade(rate_mbit=20, loss=0.02)
        config = pipeline_config(relay.address, {"endpoints": {"detector": {
            "fallback": onboard.address, "deadline_ms": 1500, "probe_interval_s": 0.5,
            "image": {"transport": "jpeg", "jpeg_quality": 80}}}})
        outputs = Outputs()
        pipeline = Pipeline(config, outputs)
        pipeline.start()
        endpoint = pipeline.endpoints["detector"]
        try:
            feed(pipeline, frames, 4)
            on_edge = len(outputs.sent)
            assert endpoint.failovers == 0 and endpoint.active is endpoint.primary
            edge.cut()
            feed_until(pipeline, frames, lambda: endpoint.failovers > 0, "never failed over")
            failed_over = len(outputs.sent)
            feed_until(pipeline, frames, lambda: len(outputs.sent) - failed_over >= 2,
                       "no counts on the fallback")
            during_cut = len(outputs.sent) - on_edge
            assert endpoint.failovers == 1 and endpoint.active is endpoint.fallback
            edge.reconnect()
            feed_until(pipeline, frames, lambda: endpoint.active is endpoint.primary,
                       "never returned to the edge")
            back = len(outputs.sent)
            feed_until(pipeline, frames, lambda: len(outputs.sent) - back >= 2,
                       "no counts on the edge again")
            after = len(outputs.sent) - back
        finally:
            pipeline.stop()
            relay.close()
    counts = [value for topic, value in outputs.sent if topic == "/human_counter"]
    # Counts in every phase: on the edge, on the fallback while cut, on the edge again.
    # How many per second, and the longest gap, are `oricf bench link`'s figures.
    assert min(on_edge, during_cut, after) >= 2, (on_edge, during_cut, after)
    assert all(2 <= c <= 12 for c in counts)
    assert endpoint.recoveries >= 1
