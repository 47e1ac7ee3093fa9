"""Placement by latency budget on a real slow path: the detector behind the project's delay
relay as the preferred place, the same detector directly as the other. Calls move when the
relay's delay pushes the preferred place's p90 over the budget (before any call fails), and
come back once the probes say it is within budget again for the hysteresis time; each
decision is counted by reason and in the metrics. The preferred place is the address, or
the fallback with `prefer: fallback`; a bad policy is refused naming the file and key."""

from __future__ import annotations

import logging
import time
from typing import Any

import pytest
from prometheus_client import generate_latest

from oricf.bench.relay import DelayRelay
from oricf.config import config_dir
from oricf.errors import ConfigError
from oricf.gateway.config import load_pipeline
from oricf.gateway.endpoints import EndpointConfig
from oricf.gateway.metrics import pipeline_registry
from oricf.gateway.pipeline import Pipeline
from oricf.gateway.values import Frame
from tests.gateway.test_pipeline import Outputs, pipeline_config
from tests.support.data import video_frames
from tests.support.services import RunningService

BUDGET_MS = 1000


def wait_for(condition: Any, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.1)
    return False


def test_calls_move_over_budget_and_return_once_back_within_it(
        caplog: pytest.LogCaptureFixture, detector: RunningService) -> None:
    frame = Frame.from_pixels(video_frames([0])[0])
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


def send(pipeline: Pipeline, frame: Frame, count: int) -> None:
    for _ in range(count):
        pipeline.submit("people", lambda: {"image": frame})
        assert pipeline.idle(30)


def test_prefer_fallback_spills_to_the_address_and_returns(
        caplog: pytest.LogCaptureFixture, detector: RunningService) -> None:
    """Onboard preferred (the fallback, slow behind the relay), the edge (the address) when
    it is over budget or fails."""
    frame = Frame.from_pixels(video_frames([0])[0])
    host, _, port = detector.address.rpartition(":")
    relay = DelayRelay((host, int(port)), delay_s=0.0)
    pipeline = Pipeline(pipeline_config(detector.address, {"endpoints": {"detector": {
        "fallback": relay.address, "deadline_ms": 10_000,
        "placement": {"latency_budget_ms": BUDGET_MS, "prefer": "fallback", "window": 5,
                      "hysteresis_s": 1.0, "probe_interval_s": 0.2}}}}), Outputs())
    endpoint = pipeline.endpoints["detector"]
    placement = endpoint.placement
    assert placement is not None
    pipeline.start()
    try:
        send(pipeline, frame, 6)
        assert endpoint.active is endpoint.fallback
        assert endpoint.answered == {"primary": 0, "fallback": 6}
        relay.delay_s = 0.6
        with caplog.at_level(logging.WARNING, "oricf.gateway.endpoints.placement"):
            send(pipeline, frame, 1)  # a window of 5: its p90 is its slowest call
            assert endpoint.active is endpoint.primary
            assert placement.decisions == {"over_budget": 1}
            assert "calls move to its address: p90" in caplog.text
            send(pipeline, frame, 2)
            assert endpoint.answered == {"primary": 2, "fallback": 7}
            relay.delay_s = 0.0
            assert wait_for(lambda: endpoint.active is endpoint.fallback, 30)
            assert "calls move to its fallback: estimated p90" in caplog.text
            relay.close()  # the preferred place goes away: the call is answered anyway
            send(pipeline, frame, 2)
        assert endpoint.active is endpoint.primary
        assert placement.decisions == {"over_budget": 1, "back_within_budget": 1,
                                       "failed": 1}
        assert "a call to its fallback failed (UNAVAILABLE)" in caplog.text
        assert pipeline.routes["people"].stats.ok == 11 and endpoint.failovers == 0
    finally:
        pipeline.stop()
        relay.close()


def test_a_placement_needs_a_fallback() -> None:
    with pytest.raises(ValueError, match="needs a fallback"):
        EndpointConfig(address="127.0.0.1:1", placement={"latency_budget_ms": 100})


@pytest.mark.parametrize(("policy", "error"), [
    ({"prefer": "edge"}, "endpoints.detector.placement.prefer: Input should be 'address' or "
                         "'fallback'"),
    ({"onboard_cpu_ceiling": 0.8}, "endpoints.detector.placement: onboard_cpu_ceiling: "
                                   "needs `onboard`"),
    ({"onboard": "robot", "onboard_cpu_ceiling": 0.8},
     "endpoints.detector.placement.onboard: Input should be 'address' or 'fallback'"),
    ({"onboard": "fallback", "onboard_cpu_ceiling": 80},
     "endpoints.detector.placement.onboard_cpu_ceiling: Input should be less than 1"),
    ({"battery_topic": "/battery_state"},
     "endpoints.detector.placement: battery_topic: needs `onboard`"),
    ({"onboard": "address", "battery_topic": "/battery", "battery_low": 20},
     "endpoints.detector.placement.battery_low: Input should be less than 1"),
])
def test_a_bad_policy_is_refused_naming_the_file_and_key(policy: dict[str, Any],
                                                         error: str) -> None:
    with pytest.raises(ConfigError) as refused:
        pipeline_config("127.0.0.1:1", {"endpoints": {"detector": {
            "fallback": "127.0.0.1:2", "placement": {"latency_budget_ms": 100, **policy}}}})
    assert f"test pipeline: {error}" in str(refused.value)


def test_the_onboard_first_overlay_prefers_the_onboard_fallback() -> None:
    pipelines = config_dir() / "pipelines"
    placed = load_pipeline(pipelines / "people_qa.yaml",
                           [pipelines / "placement" / "onboard_first.yaml"])
    detector = placed.endpoints["detector"]
    assert detector.placement is not None and detector.fallback == "127.0.0.1:50051"
    assert detector.placement.prefer == detector.placement.onboard == "fallback"
    assert detector.placement.onboard_cpu_ceiling == 0.8
    edge = load_pipeline(pipelines / "people_qa.yaml", [pipelines / "placement" / "edge.yaml"])
    assert placed.endpoints["detector"].model_copy(update={"placement": None}) \
        == edge.endpoints["detector"]  # the same places as edge.yaml, the other way round
