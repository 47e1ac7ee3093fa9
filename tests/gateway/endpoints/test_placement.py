"""Placement by latency budget on a real slow path: the detector behind the project's delay
relay as the preferred endpoint, the same detector directly as the fallback. Calls move to
the fallback when the relay's delay pushes the primary's p90 over the budget (before any
call fails), and come back once the probes say the primary is within budget again for the
hysteresis time; each decision is counted by reason and in the metrics."""

from __future__ import annotations

import logging
import time
from typing import Any

import pytest
from prometheus_client import generate_latest

from oricf.bench.relay import DelayRelay
from oricf.gateway.endpoints import EndpointConfig
from oricf.gateway.metrics import pipeline_registry
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame
from tests.gateway.test_pipeline import Outputs, pipeline_config
from tests.support.data import video_frames
from tests.support.services import running_service

BUDGET_MS = 1000


def wait_for(condition: Any, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.1)
    return False


def test_calls_move_over_budget_and_return_once_back_within_it(
        caplog: pytest.LogCaptureFixture) -> None:
    frame = Frame.from_pixels(video_frames([0])[0])
    with running_service("detector") as detector:
        host, _, port = detector.address.rpartition(":")
        relay = DelayRelay((host, int(port)), delay_s=0.0)
        pipeline = Pipeline(pipeline_config(relay.address, {"endpoints": {"detector": {
            "fallback": detector.address, "deadline_ms": 10_000,
            "placement": {"latency_budget_ms": BUDGET_MS, "window": 5, "hysteresis_s": 1.0,
                          "probe_interval_s": 0.2}}}}), Outputs())
        endpoint = pipeline.endpoints["detector"]
        placement = endpoint.placement
        assert placement is not None

        def frames(count: int) -> None:
            for _ in range(count):
                pipeline.submit("people", lambda: {"image": frame})
                assert pipeline.idle(30)

        pipeline.start()
        try:
            frames(6)  # a clean link: the primary, within budget
            assert endpoint.active is endpoint.primary and not placement.decisions
            relay.delay_s = 0.6  # each way: every call about 1.2 s, over the budget
            with caplog.at_level(logging.WARNING, "oricf.gateway.endpoints.placement"):
                frames(5)
                assert endpoint.active is endpoint.fallback
                assert placement.decisions == {"over_budget": 1}
                assert "over the budget of 1000 ms" in caplog.text
                started = time.monotonic()
                frames(1)  # on the fallback: fast again
                assert time.monotonic() - started < 1.0
                assert endpoint.failovers == 0  # nothing failed: moved by the budget
                time.sleep(3)  # the probes still see the slow path: calls stay
                assert endpoint.active is endpoint.fallback
                relay.delay_s = 0.0
                assert wait_for(lambda: endpoint.active is endpoint.primary, 30)
            assert placement.decisions == {"over_budget": 1, "back_within_budget": 1}
            assert "within the budget for 1 s" in caplog.text
            frames(1)
            assert pipeline.routes["people"].stats.ok == 13
            metrics = generate_latest(pipeline_registry(pipeline)).decode()
            for reason in ("over_budget", "back_within_budget"):
                assert (f'oricf_gateway_endpoint_placements_total{{endpoint="detector",'
                        f'reason="{reason}"}} 1.0') in metrics
        finally:
            pipeline.stop()
            relay.close()


def test_a_placement_needs_a_fallback() -> None:
    with pytest.raises(ValueError, match="needs a fallback"):
        EndpointConfig(address="127.0.0.1:1", placement={"latency_budget_ms": 100})
