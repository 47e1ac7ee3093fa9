"""A control loop's policy placed by a budget in control steps: pybullet's Hopper policy on
the "edge" (the policy service behind the delay relay) and "onboard" (the same service
directly). Over a one-step budget (16.5 ms at 60.6 Hz) a 30 ms edge loses its calls to
onboard, saying why in steps; with `hedge`, a call the edge has not answered by the budget
is answered onboard at once, each counted. A budget in steps on an endpoint no control input
calls is refused naming the key."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import pytest

from oricf.bench.relay import DelayRelay
from oricf.errors import ConfigError
from oricf.gateway.components import METHODS
from oricf.gateway.config import PipelineConfig, parse_pipeline
from oricf.gateway.endpoints import Endpoint
from oricf.gateway.operations.view import placement_status
from oricf.gateway.products import ProductStore
from tests.support.services import RunningService

RATE_HZ = 60.606


def config(edge: str, onboard: str, **placement: Any) -> PipelineConfig:
    return parse_pipeline({
        "endpoints": {"hopper": {
            "address": edge, "fallback": onboard, "deadline_ms": 2000,
            "placement": {"latency_budget_steps": 1, "onboard": "fallback", "window": 5,
                          "probe_interval_s": 60, **placement}}},
        "routes": {"hopper": {
            "input": {"control": {
                "rate_hz": RATE_HZ, "action_dim": 3,
                "state": [{"topic": "/s", "type": "std_msgs/Float64MultiArray"}],
                "target": {"topic": "/a"}}},
            "call": {"method": "Act", "service": "hopper"}}}}, "placement test")


def act(pipeline_config: PipelineConfig, state: np.ndarray) -> tuple[Endpoint, Any]:
    endpoint = Endpoint("hopper", pipeline_config.endpoints["hopper"], METHODS["Act"],
                        pipeline_config.step_of("hopper"))
    call = pipeline_config.routes["hopper"].call
    invoke = METHODS["Act"].open(call, endpoint, ProductStore())
    return endpoint, lambda step: invoke({"state": state, "step": step})


def test_an_edge_over_a_one_step_budget_loses_the_policy_to_onboard(
        policy: RunningService, hopper_state: np.ndarray,
        caplog: pytest.LogCaptureFixture) -> None:
    host, _, port = policy.address.rpartition(":")
    relay = DelayRelay((host, int(port)), delay_s=0.015)  # each way: a 30 ms round trip
    endpoint, call = act(config(relay.address, policy.address), hopper_state)
    placement = endpoint.placement
    assert placement is not None and placement.budget_ms == pytest.approx(16.5, abs=0.01)
    try:
        with caplog.at_level(logging.WARNING, "oricf.gateway.endpoints.placement"):
            for step in range(12):
                chunk = call(step)
                assert chunk.actions.shape == (1, 3) and chunk.observation_step == step
        assert placement.decisions["over_budget"] == 1
        assert endpoint.active is endpoint.fallback
        assert endpoint.answered["fallback"] > 0
        assert "over the budget of 16.5 ms (1 steps at 60.606 Hz)" in caplog.text
        assert placement_status(endpoint) == {"placement": {
            "place": "fallback", "budget_ms": 16.5, "moves": {"over_budget": 1}}}
    finally:
        endpoint.close()
        relay.close()


def test_hedged_calls_take_the_onboard_answer_at_the_budget(
        policy: RunningService, hopper_state: np.ndarray,
        caplog: pytest.LogCaptureFixture) -> None:
    host, _, port = policy.address.rpartition(":")
    relay = DelayRelay((host, int(port)), delay_s=0.05)  # 100 ms: far over 2 steps
    endpoint, call = act(config(relay.address, policy.address, latency_budget_steps=2,
                                hedge=True, window=1000), hopper_state)
    placement = endpoint.placement
    assert placement is not None
    try:
        with caplog.at_level(logging.WARNING, "oricf.gateway.endpoints.placement"):
            for step in range(3):
                assert call(step).observation_step == step
        assert placement.decisions["hedged"] == 3
        assert endpoint.answered == {"primary": 0, "fallback": 3}
        assert "answered by its fallback" in caplog.text
    finally:
        endpoint.close()
        relay.close()


def test_a_budget_in_steps_needs_a_control_input() -> None:
    with pytest.raises(ConfigError, match=r"endpoints\.d\.placement\.latency_budget_steps: "
                                          r"no control input calls this endpoint"):
        parse_pipeline({
            "endpoints": {"d": {"address": "127.0.0.1:1", "fallback": "127.0.0.1:2",
                                "placement": {"latency_budget_steps": 2}}},
            "routes": {"r": {"input": {"text": "-"},
                             "call": {"method": "Detect", "service": "d"},
                             "outputs": [{"text": "-", "from": "detections"}]}}}, "test")
    with pytest.raises(ConfigError, match="exactly one of latency_budget_ms or "
                                          "latency_budget_steps"):
        config("127.0.0.1:1", "127.0.0.1:2", latency_budget_ms=10)
